"""Command line: ``fiberpipe run CONFIG``, one subcommand per stage, ``inspect``, ``verify``...

The CLI is a thin layer over :mod:`fiberpipe.pipeline` and :mod:`fiberpipe.stages`. A
:class:`~fiberpipe.errors.FiberpipeError` (bad config, bad input, wrong artifact) is printed as
one line on stderr with a non-zero exit status; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import io
import json
import logging
import os
import sys
from pathlib import Path

import click

from fiberpipe import __version__
from fiberpipe.errors import FiberpipeError


class _Terminated(BaseException):
    """SIGTERM outside the solver's step loop (which checkpoints on it): raised in the main thread so
    that every file being written atomically is cleaned up on the way out, as on Ctrl-C."""


def _raise_terminated(signum, frame):
    raise _Terminated()


class _Group(click.Group):
    """Turns user errors into one line (no traceback) unless ``--debug``."""

    def invoke(self, ctx):
        import signal
        import threading

        in_main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGTERM, _raise_terminated) if in_main else None
        try:
            rv = super().invoke(ctx)
            sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
            return rv
        except _Terminated:
            click.echo("terminated", err=True)
            sys.exit(143)  # 128 + SIGTERM
        except click.UsageError as exc:  # a subcommand's bad option or argument: one line, as every error
            where = exc.ctx.command_path if exc.ctx is not None else "fiberpipe"
            click.echo(f"error: {exc.format_message()} (see {where} --help)", err=True)
            sys.exit(exc.exit_code)
        except BrokenPipeError:  # `fiberpipe inspect X | head`: the reader is gone, stop quietly
            _silence_stdout()
            sys.exit(141)  # 128 + SIGPIPE, as a tool killed by the signal
        except FiberpipeError as exc:
            if ctx.obj and ctx.obj.get("debug"):
                raise
            click.echo(f"error: {exc}", err=True)
            sys.exit(exc.exit_code)
        except KeyboardInterrupt:
            click.echo("interrupted", err=True)
            sys.exit(130)
        except MemoryError:
            click.echo("error: out of memory", err=True)
            sys.exit(2)
        except (OSError, ValueError) as exc:
            if ctx.obj and ctx.obj.get("debug"):
                raise
            click.echo(f"error: {type(exc).__name__}: {exc}", err=True)
            sys.exit(2)
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that flushing it at exit does not raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        pass


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="fiberpipe")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bars or per-stage lines (warnings and errors only).")
@click.pass_context
def main(ctx, debug, quiet):
    """fiberpipe: from a tomography volume of a fiber bundle to its simulated compaction curve."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug
    ctx.obj["quiet"] = quiet
    # progress bars only on a terminal (CI and logs stay quiet); per-stage lines unless --quiet
    ctx.obj["progress"] = not quiet and _stderr_is_terminal()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    for handler in logging.getLogger().handlers:  # the console shows warnings; run.log gets everything
        handler.setLevel(logging.WARNING)


def _opts() -> dict:
    ctx = click.get_current_context(silent=True)
    return (ctx.find_root().obj if ctx is not None else None) or {}


def _echo(line: str) -> None:
    """Per-stage and progress lines: printed unless --quiet; a warning is printed always (stderr)."""
    if line.startswith("warning:"):
        click.echo(line, err=True) if _opts().get("quiet") else click.echo(line)
    elif not _opts().get("quiet"):
        click.echo(line)


def _stderr_is_terminal() -> bool:
    return sys.stderr.isatty()


def _progress() -> bool:
    return bool(_opts().get("progress"))


def _load(config):
    from fiberpipe.config import load_config

    cfg = load_config(config)
    for w in cfg.scene.warnings():
        click.echo(f"warning: {w}", err=True)
    return cfg


def _with_scheduler(cfg, scheduler):
    """``--scheduler`` over ``chunks.scheduler`` (where the chunked stages run, not what they compute)."""
    if scheduler:
        cfg.chunks.scheduler = scheduler
    return cfg


def _default_out(config) -> Path:
    return Path("runs") / Path(config).stem


@main.command()
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--out", "out", type=click.Path(file_okay=False), help="Run folder (default: runs/<config name>).")
@click.option("--from", "from_stage", help="First stage to run.")
@click.option("--to", "to_stage", help="Last stage to run.")
@click.option("--force", is_flag=True, help="Rerun stages even when their inputs and settings are unchanged.")
@click.option("--scheduler", help="Address of a Dask scheduler: the chunked imaging stages run their slabs there "
              "(chunks.scheduler), an ensemble its runs.")
@click.option("--seeds", help="An ensemble of specimens (replaces specimen.seeds): N seeds from specimen.seed on, "
              "or a list 0,1,2; F(U) as their mean with a band.")
@click.pass_context
def run(ctx, config, out, from_stage, to_stage, force, scheduler=None, seeds=None):
    """Run the stages CONFIG asks for, skipping those that are up to date."""
    from fiberpipe.pipeline import run_pipeline

    if seeds is not None or _has_ensemble(config):
        if from_stage or to_stage or force:
            from fiberpipe.errors import ConfigError

            raise ConfigError("--from, --to and --force apply to one run, not to an ensemble (specimen.seeds, --seeds): "
                              "each of its runs is up to date or runs")
        return _run_ensemble(config, out, seeds, scheduler)
    cfg = _with_scheduler(_load(config), scheduler)
    out = Path(out) if out else _default_out(config)
    run_pipeline(cfg, out, from_stage=from_stage, to_stage=to_stage, force=force, echo=_echo, progress=_progress())
    _echo(f"run folder: {out}")


def _has_ensemble(config) -> bool:
    """CONFIG asks for an ensemble (specimen.seeds); a file that cannot be read says so in the run."""
    from fiberpipe.config import load_raw

    try:
        specimen = load_raw(config).get("specimen")
    except FiberpipeError:
        return False
    return isinstance(specimen, dict) and specimen.get("seeds") is not None


def _run_ensemble(config, out, seeds, scheduler) -> None:
    """``run`` of an ensemble: one specimen per seed, built and compacted (fiberpipe.studies.ensemble)."""
    from fiberpipe.artifacts import ensure_output_dir
    from fiberpipe.config import load_raw
    from fiberpipe.studies.ensemble import ensemble_seeds, run_ensemble

    raw = load_raw(config)
    seed_list = ensemble_seeds(raw, seeds, str(config))
    out = Path(out) if out else _default_out(config)
    ensure_output_dir(out)
    run_ensemble(raw, seed_list, out, scheduler=scheduler, where=str(config), echo=_echo)
    _echo(f"ensemble folder: {out} (ensemble.csv, ensemble.json, ensemble.png)")


def _stage_command(name: str, doc: str):
    @click.argument("config", type=click.Path(dir_okay=False))
    @click.option("--out", "out", type=click.Path(file_okay=False), help="Run folder (default: runs/<config name>).")
    @click.option("--force", is_flag=True, help="Rerun even if up to date.")
    @click.pass_context
    def cmd(ctx, config, out, force, scheduler=None):
        from fiberpipe.pipeline import run_pipeline

        cfg = _with_scheduler(_load(config), scheduler)
        out = Path(out) if out else _default_out(config)
        run_pipeline(cfg, out, from_stage=name, to_stage=name, force=force, echo=_echo, progress=_progress())

    cmd.__doc__ = doc + " Reads its inputs from, and writes into, the run folder."
    if name in ("segment", "skeletonize"):  # the stages that run chunk by chunk
        cmd = click.option("--scheduler", help="Address of a Dask scheduler for the chunked imaging stages "
                           "(chunks.scheduler).")(cmd)
    return main.command(name=name)(cmd)


_stage_command("segment", "Segment the volume into a fiber mask (mask.h5).")
_stage_command("skeletonize", "Thin the mask to a skeleton with local radii (skeleton.h5).")
_stage_command("mesh", "Mesh the fibers into beam elements (mesh.h5, mesh.vtu, model.inp).")


@main.command("simulate")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--out", "out", type=click.Path(file_okay=False), help="Run folder (default: runs/<config name>).")
@click.option("--force", is_flag=True, help="Rerun even if up to date; discards a checkpoint.")
@click.option("--resume", is_flag=True, help="Continue from the run folder's simulation.checkpoint.h5 (same config and mesh).")
def simulate_command(config, out, force, resume):
    """Simulate the scene on the mesh (simulation.h5, frames/*.vtu, simulation.pvd).

    Reads its inputs from, and writes into, the run folder. Writes simulation.checkpoint.h5 every
    solver.checkpoint_every steps and on Ctrl-C/SIGTERM (exit status 130/143); without --resume a
    checkpoint of the same config is picked up too, --force discards it.
    """
    from fiberpipe.errors import ConfigError
    from fiberpipe.pipeline import run_pipeline

    if resume and force:
        raise ConfigError("--resume and --force contradict each other (--force discards the checkpoint)")
    cfg = _load(config)
    out = Path(out) if out else _default_out(config)
    run_pipeline(cfg, out, from_stage="simulate", to_stage="simulate", force=force, echo=_echo,
                 resume="require" if resume else None, progress=_progress())

_stage_command("post", "Post-process a simulation: curves, energies, plots, report (post/).")


@main.command()
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--out", "out", type=click.Path(file_okay=False), help="Run folder (default: runs/<config name>).")
@click.option("--force", is_flag=True, help="Rerun even if up to date.")
@click.option("--truth", type=click.Path(dir_okay=False), help="Ground-truth fibers.h5: print the tracing accuracy.")
@click.option("--scheduler", help="Address of a Dask scheduler: the chunked imaging stages run their slabs there (chunks.scheduler).")
def trace(config, out, force, truth, scheduler=None):
    """Trace one mid-line per fiber from the mask (fibers.h5)."""
    from fiberpipe.pipeline import run_pipeline
    from fiberpipe.stages.trace import trace_accuracy_report

    cfg = _with_scheduler(_load(config), scheduler)
    out = Path(out) if out else _default_out(config)
    run_pipeline(cfg, out, from_stage="trace", to_stage="trace", force=force, echo=_echo, progress=_progress())
    if truth:
        from fiberpipe.artifacts import read_artifact
        from fiberpipe.stages.skeletonize import eval_list

        vs = eval_list(read_artifact(out / "mask.h5", "mask", names=()).attrs["voxel_size_m"])[0]
        acc = trace_accuracy_report(out / "fibers.h5", Path(truth), vs, out / "trace_accuracy.json")
        for k, v in acc.items():
            if not isinstance(v, (list, tuple, dict)):  # the per-fiber matches are in the JSON file
                click.echo(f"{k:28s} {v}")
        click.echo(f"{'written to':28s} {out / 'trace_accuracy.json'}")


@main.command()
@click.option("--out", "out", type=click.Path(file_okay=False), required=True, help="Folder for volume.tif and truth.h5.")
@click.option("--n-fibers", default=16, show_default=True, type=int)
@click.option("--shape", nargs=3, type=int, default=(150, 64, 64), show_default=True, help="z y x voxels")
@click.option("--radius-vox", default=4.0, show_default=True, type=float)
@click.option("--voxel-size", default="62.5 um", show_default=True, help="Quantity, e.g. '15 um'.")
@click.option("--touching-fraction", default=1 / 3, show_default=True, type=float)
@click.option("--cnr", "contrast_to_noise", default=5.0, show_default=True, type=float, help="Contrast-to-noise ratio.")
@click.option("--blur", "blur_sigma_vox", default=1.0, show_default=True, type=float, help="PSF sigma, voxels.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0))
@click.option("--from-simulation", "from_simulation", type=click.Path(dir_okay=False),
              help="Render a frame of this simulation.h5 instead (closes the loop: trace it again).")
@click.option("--frame", default=-1, show_default=True, type=int, help="Frame index for --from-simulation.")
def phantom(out, from_simulation, frame, **kw):
    """Make a synthetic CT volume of curved, touching fibers with its ground truth.

    With --from-simulation, render a simulated frame instead; truth.h5 then holds that frame's
    mid-lines in the volume's coordinates (origin of voxel 0 in the 'origin_m' attribute).
    """
    from fiberpipe.config import PhantomConfig
    from fiberpipe.errors import ConfigError
    from fiberpipe.artifacts import ensure_output_dir
    from fiberpipe.stages.phantom import run_phantom

    if from_simulation:
        from fiberpipe.stages.phantom import render_simulation_frame
        from fiberpipe.units import to_si

        try:
            vs = to_si(kw["voxel_size"], "length")
        except ValueError as exc:
            raise ConfigError(f"--voxel-size: {exc}") from None
        if not vs > 0:
            raise ConfigError(f"--voxel-size {kw['voxel_size']}: must be positive")
        figures = render_simulation_frame(Path(from_simulation), frame, vs, Path(out), contrast_to_noise=kw["contrast_to_noise"],
                                          blur_sigma_vox=kw["blur_sigma_vox"], seed=kw["seed"])
        click.echo(f"wrote {out}/volume.tif and {out}/truth.h5: frame {figures['frame']}, shape {figures['shape']}")
        return

    from pydantic import ValidationError

    kw["shape"] = list(kw["shape"])
    try:
        pcfg = PhantomConfig(**kw)
    except ValidationError as exc:
        raise ConfigError(_phantom_option_error(exc)) from None
    ensure_output_dir(out)
    figures = run_phantom(pcfg, Path(out))
    click.echo(f"wrote {out}/volume.tif and {out}/truth.h5: {figures['fibers']} fibers, shape {figures['shape']}")


#: The phantom command's option for each PhantomConfig field.
_PHANTOM_OPTIONS = {
    "n_fibers": "--n-fibers", "shape": "--shape", "radius_vox": "--radius-vox", "voxel_size": "--voxel-size",
    "touching_fraction": "--touching-fraction", "contrast_to_noise": "--cnr", "blur_sigma_vox": "--blur", "seed": "--seed",
}


def _phantom_option_error(exc) -> str:
    """One line from a pydantic ValidationError of PhantomConfig: the option, what is wrong, the value."""
    import re

    errors = exc.errors()
    lines = []
    for err in errors:
        field_name = str(err["loc"][0]) if err.get("loc") else ""
        msg = err["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        if not field_name:
            # a check across fields (does the fiber fit the shape?) names the config keys: on this
            # command they are options ("input.phantom.radius_vox = 8" -> "--radius-vox 8")
            msg, n = re.subn(r"\binput\.phantom\.(\w+)( = )?",
                             lambda m: _PHANTOM_OPTIONS.get(m[1], m[1]) + (" " if m[2] else ""), msg)
            msg, k = re.subn(r"\b(" + "|".join(f for f in _PHANTOM_OPTIONS if "_" in f) + r")\b",
                             lambda m: _PHANTOM_OPTIONS[m[1]], msg)
            lines.append(msg if n + k else f"phantom options: {msg}")
            continue
        opt = _PHANTOM_OPTIONS.get(field_name, field_name)
        if "input" in err and "got" not in msg and str(err["input"]) not in msg:
            msg += f", got {err['input']!r}"
        if msg.startswith("Input should be "):
            lines.append(f"{opt} must be {msg[len('Input should be '):]}")
        else:
            lines.append(f"{opt}: {msg}")
    more = f" (and {len(lines) - 1} more problem{'s' if len(lines) > 2 else ''})" if len(lines) > 1 else ""
    return lines[0] + more if lines else "invalid phantom options"


@main.command()
@click.argument("run_dirs", nargs=-1, required=True, type=click.Path(file_okay=False))
@click.option("--out", "out", type=click.Path(file_okay=False), required=True, help="Folder for comparison.png and comparison.md.")
def compare(run_dirs, out):
    """Gather the force-displacement curves of several run folders into one plot and table."""
    from fiberpipe.post.compare import compare_runs

    click.echo(compare_runs([Path(d) for d in run_dirs], Path(out)))


@main.command()
@click.argument("artifact", type=click.Path(dir_okay=False))
@click.option("--check", is_flag=True, help="Verify the artifact's integrity and the hashes of its inputs.")
def inspect(artifact, check):
    """Print an artifact's kind, schema version, provenance and contents."""
    from fiberpipe.inspect import inspect_artifact

    ok = inspect_artifact(Path(artifact), check=check, echo=click.echo)
    if not ok:
        sys.exit(1)


@main.command()
@click.argument("study_file", type=click.Path(dir_okay=False))
@click.option("--out", "out", type=click.Path(file_okay=False), help="Study folder (default: runs/studies/<name>).")
@click.option("--workers", type=click.IntRange(min=1), help="Points run in parallel (local processes, or Dask workers).")
@click.option("--scheduler", help="Address of an existing Dask scheduler (needs fiberpipe[dask]).")
@click.option("--seeds", help="Every point an ensemble of specimens (replaces the base's specimen.seeds): N seeds "
              "from specimen.seed on, or a list 0,1,2.")
def study(study_file, out, workers, scheduler, seeds):
    """Sweep config keys; table and Pareto plot of error against wall time (docs/accuracy-cost.md)."""
    from fiberpipe.studies.sweep import run_study

    from fiberpipe.artifacts import ensure_output_dir

    out = Path(out) if out else Path("runs") / "studies" / Path(study_file).stem
    created = not out.exists()
    ensure_output_dir(out)
    try:
        run_study(study_file, out, workers=workers, scheduler=scheduler, echo=_echo, seeds=seeds)
    except BaseException:
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # a bad study file leaves no empty folder behind
        raise
    _echo(f"study folder: {out} (study.csv, study.md, pareto.png)")


@main.command()
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--target", required=True, type=click.Path(dir_okay=False), help="CSV with columns U_m,load_N.")
@click.option("--param", "params", multiple=True, required=True, metavar="KEY=LO:HI",
              help="A config key (specimen keys too) and its bounds, units accepted; repeatable.")
@click.option("--seeds", help="Specimen seeds the curve is averaged over: N from specimen.seed on, or a list 0,1,2 "
              "(default: specimen.seeds, else 1).")
@click.option("--budget", default=20, show_default=True, type=int, help="Largest number of evaluations.")
@click.option("--out", "out", type=click.Path(file_okay=False), help="Folder (default: runs/fits/<config name>).")
@click.option("--workers", default=1, show_default=True, type=click.IntRange(min=1), help="Runs in parallel (local processes).")
@click.option("--scheduler", help="Address of an existing Dask scheduler (needs fiberpipe[dask]).")
def fit(config, target, params, seeds, budget, out, workers, scheduler):
    """Fit config keys so that the simulated load matches a measured curve (fit.json, fit.png, history.csv)."""
    from fiberpipe.artifacts import ensure_output_dir
    from fiberpipe.studies.fit import run_fit

    out = Path(out) if out else Path("runs") / "fits" / Path(config).stem
    created = not out.exists()
    ensure_output_dir(out)
    try:
        run_fit(config, target, list(params), seeds=seeds, budget=budget, out=out, workers=workers,
                scheduler=scheduler, echo=_echo)
    except BaseException:
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # bad input leaves no empty folder behind
        raise


@main.command()
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--out", "out", type=click.Path(file_okay=False), help="Folder (default: runs/specimens/<config name>).")
@click.option("--seed", type=click.IntRange(min=0), help="Replaces specimen.seed.")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help="Override a config key (repeatable), e.g. specimen.n_fibers=400.")
def specimen(config, out, seed, sets):
    """Build the virtual specimen of CONFIG's specimen section: fibers.h5, specimen.json and a ready config.yaml."""
    from fiberpipe.errors import ConfigError
    from fiberpipe.model.virtual_specimen import run_specimen_command
    from fiberpipe.artifacts import ensure_output_dir

    overrides = {}
    for item in sets:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE")
        overrides[key.strip()] = yaml_value(value)
    out = Path(out) if out else Path("runs") / "specimens" / Path(config).stem
    created = not out.exists()
    ensure_output_dir(out)
    try:
        run_specimen_command(config, out, seed=seed, overrides=overrides, echo=click.echo, progress=_progress())
    except BaseException:
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # a refused specimen leaves no empty folder behind
        raise


def yaml_value(text: str):
    """A command-line value read as YAML (``400`` an int, ``"60 mm"`` a string, ``[a, b]`` a list)."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


@main.command()
@click.option("--quick", is_flag=True, help="Small sizes and short runs only (minutes, not the headline figures).")
@click.option("--skip", multiple=True, type=click.Choice(["solver", "contact", "pyelastica", "paper40", "imaging",
                                                         "threads"]),
              help="Leave out a part (repeatable).")
@click.option("--out", type=click.Path(dir_okay=False), default=None,
              help="Page to write (default docs/benchmarks.md of a source checkout, else ./benchmarks.md).")
def bench(quick, skip, out):
    """Performance benchmarks into docs/benchmarks.md: solver element-steps/s
    (40/160/640 fibers, contact off/on), contact cost per pair, PyElastica ratio, paper-40
    time-to-solution, imaging throughput and memory, and two threads against one. Run it on an idle
    machine."""
    from fiberpipe.bench import run_bench

    try:
        text = run_bench(out, quick=quick, skip=tuple(skip), echo=click.echo)
    except FileNotFoundError as exc:
        raise FiberpipeError(str(exc)) from None
    click.echo(text)


@main.command()
@click.option("--quick", is_flag=True, help="Only the fast cases.")
def verify(quick):
    """Run the verification cases (docs/verification.md) and print the table."""
    try:
        from fiberpipe.verification import __main__ as vmain
    except ImportError:
        raise FiberpipeError("verification cases are not available in this version yet") from None
    sys.exit(vmain.main(["--quick"] if quick else []))


@main.command()
@click.option("--quick", is_flag=True, help="The quick variants (the default test suite's; seconds to a minute).")
@click.option("--out", type=click.Path(file_okay=False), default="runs/validation", show_default=True,
              help="Folder for summary.json, validation.md and the figure.")
@click.option("--docs", "docs_page", type=click.Path(dir_okay=False), default=None,
              help="Also write the table into this page's generated section (make validate: docs/validation.md).")
@click.option("--seeds", default=None,
              help="Specimen seeds of the compaction cases, comma-separated (a law is judged on their mean; "
                   "default 0,1,2, with --quick 0).")
@click.option("--reuse", is_flag=True,
              help="Read the runs already in DIR/work and leave out the seeds without one (runs nothing new).")
@click.argument("cases", nargs=-1)
def validate(quick, out, docs_page, seeds, reuse, cases):
    """Bundle-scale virtual experiments against published compaction laws (docs/validation.md):
    reference and source, tolerance, measured value (mean ± spread over the seeds), pass or fail.
    Exit status 1 when a checked row fails."""
    from fiberpipe.validation.registry import run_cases, write_outputs

    try:
        seed_list = None if seeds is None else [int(s) for s in seeds.split(",")]
    except ValueError:
        raise FiberpipeError(f"validate: --seeds must be integers separated by commas, got {seeds!r}") from None
    summary = run_cases(cases or None, quick=quick, echo=_echo, work=Path(out) / ("work-quick" if quick else "work"),
                        seeds=seed_list, reuse_only=reuse)
    write_outputs(summary, Path(out), docs_page=Path(docs_page) if docs_page else None)
    _echo(f"{summary['passed']}/{summary['checked']} checked rows pass; {out}/summary.json")
    sys.exit(0 if summary["passed"] == summary["checked"] else 1)


@main.group()
def export():
    """Write a config's scene, or traced fibers, in another program's format."""


@export.command("abaqus")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--out", "out_file", type=click.Path(dir_okay=False),
              help="Deck to write (default: model.inp in the run folder).")
@click.option("--run", "run_dir", type=click.Path(file_okay=False),
              help="Run folder for the stages up to mesh (default: runs/<config name>).")
def export_abaqus(config, out_file, run_dir):
    """The scene of CONFIG as a complete Abaqus/Explicit input deck (docs/abaqus.md): runs the
    stages up to mesh (cached), then writes fibers, plates, walls, contact, loading, step and
    outputs."""
    from fiberpipe.artifacts import ensure_output_dir, read_mesh
    from fiberpipe.io.abaqus import write_abaqus_deck
    from fiberpipe.pipeline import run_pipeline

    cfg = _load(config)
    run_dir = Path(run_dir) if run_dir else _default_out(config)
    out_file = Path(out_file) if out_file else run_dir / "model.inp"
    # both folders can be written, before the stages run
    ensure_output_dir(out_file.parent)
    ensure_output_dir(run_dir, option="--run")
    run_pipeline(cfg, run_dir, to_stage="mesh", echo=_echo, progress=_progress())
    figures = write_abaqus_deck(out_file, cfg, read_mesh(run_dir / "mesh.h5"))
    fit = figures.get("contact_fit_error_full_scale")
    _echo(f"Abaqus/Explicit deck: {out_file} (time period {figures['time_period_s']:.6g} s"
          + ("" if fit is None else f"; contact table fit error {100 * fit:.3g} % of full scale") + ")")


def _fiber_export_command(fmt: str, what: str):
    """``fiberpipe export FORMAT FIBERS.h5 [--out FILE]``: traced fibers for another program
    (fiberpipe.io.writers)."""
    @export.command(fmt, help=f"The fibers of FIBERS_H5 (a fibers.h5 artifact) for {what}.")
    @click.argument("fibers_h5", type=click.Path(dir_okay=False))
    @click.option("--out", "out_file", type=click.Path(dir_okay=False), help="File to write (default: beside FIBERS_H5).")
    def command(fibers_h5, out_file):
        from fiberpipe.io.writers import export_fibers

        _echo(f"{what}: {export_fibers(fmt, fibers_h5, out_file)}")


for _fmt, _writer in __import__("fiberpipe.io.writers", fromlist=["FIBER_WRITERS"]).FIBER_WRITERS.items():
    _fiber_export_command(_fmt, _writer.what)


if __name__ == "__main__":
    main()
