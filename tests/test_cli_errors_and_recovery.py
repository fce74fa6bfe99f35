"""The command-line layer on bad options, damaged outputs, unwritable folders and interruptions:
each is a one-line error (or the right behaviour) through the CLI, never a traceback or a
misleading message."""

import json
import shutil
from pathlib import Path

import pytest


from _scenes import cli, run_small, small_scene, write_cfg

TIP = {
    "name": "tip",
    "input": {"polylines": [[[0, 0, 0], ["3 mm", 0, 0]], [[0, "1 mm", 0], ["3 mm", "1 mm", 0]]]},
    "fiber": {"radius": "0.25 mm"},
    "mesh": {"element_length": "0.3 mm"},
}


def one_line_error(result) -> str:
    assert result.exit_code != 0, result.output
    assert "Traceback" not in result.output
    errors = [ln for ln in result.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, result.output
    return errors[0]


# -- 1. out-of-range phantom options name the option and what is wrong ---------------------------


@pytest.mark.parametrize("args, message", [
    (["--radius-vox", "-3"], "--radius-vox must be greater than 0.5, got -3.0"),
    (["--n-fibers", "0"], "--n-fibers must be greater than or equal to 1, got 0"),
    (["--cnr", "0"], "--cnr must be greater than 0, got 0.0"),
    (["--blur", "-1"], "--blur must be greater than or equal to 0, got -1.0"),
    (["--touching-fraction", "2"], "--touching-fraction must be less than or equal to 1, got 2.0"),
    (["--shape", "0", "0", "0"], "--shape: shape must be 3 sizes (z y x) of at least 8 voxels"),
    (["--voxel-size", "3 kg"], "--voxel-size: '3 kg' has units of [mass], but a length"),
    (["--n-fibers", "0", "--cnr", "0"], "(and 1 more problem)"),
])
def test_phantom_option_errors_name_the_option(tmp_path, args, message):
    line = one_line_error(cli("phantom", "--out", tmp_path / "ph", *args))
    assert message in line, line
    assert "pydantic" not in line
    assert not (tmp_path / "ph").exists()


def test_phantom_that_does_not_fit_names_the_options(tmp_path):
    # the check across fields is worded for input.phantom in a config; the command names its options
    line = one_line_error(cli("phantom", "--out", tmp_path / "ph", "--shape", "10", "10", "10", "--radius-vox", "8"))
    assert line.startswith("error: --radius-vox 8 voxels does not fit --shape (y and x need at least 19 voxels"), line
    assert line.endswith("lower --radius-vox to at most 3.5"), line
    assert "input.phantom" not in line and "radius_vox" not in line and "phantom options" not in line
    assert not (tmp_path / "ph").exists()


# -- 2. --quiet: no per-stage lines, no progress bars --------------------------------------------


def test_quiet_prints_no_stage_lines(tmp_path, monkeypatch):
    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    r = cli("-q", "run", cfg, "--out", tmp_path / "run")
    assert r.exit_code == 0, r.output
    assert r.output == ""
    assert (tmp_path / "run" / "mesh.h5").exists()
    r = cli("run", cfg, "--out", tmp_path / "run")  # without it: one line per stage
    assert "mesh         up to date" in r.output and "run folder:" in r.output
    # and no progress bar is asked for, even on a terminal (where one is asked for without --quiet)
    import fiberpipe.cli as C
    import fiberpipe.pipeline as P

    seen = {}
    monkeypatch.setattr(P, "run_pipeline", lambda *a, **kw: seen.update(kw))
    monkeypatch.setattr(C, "_stderr_is_terminal", lambda: True)
    assert cli("run", cfg, "--out", tmp_path / "run").exit_code == 0
    assert seen["progress"] is True
    assert cli("--quiet", "run", cfg, "--out", tmp_path / "run").exit_code == 0
    assert seen["progress"] is False


# -- 3. a damaged or wrong-kind output is not "up to date" ---------------------------------------


@pytest.mark.parametrize("damage, message", [
    (lambda out: out.joinpath("mesh.h5").write_bytes(out.joinpath("mesh.h5").read_bytes()[:2000]),
     "mesh.h5: is not a readable HDF5 artifact"),
    (lambda out: shutil.copy(out / "fibers.h5", out / "mesh.h5"), "mesh.h5: is a fibers artifact, but a mesh artifact is needed"),
    (lambda out: out.joinpath("model.inp").write_bytes(b""), "output model.inp is empty"),
])
def test_damaged_output_is_rerun_not_up_to_date(tmp_path, damage, message):
    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    out = tmp_path / "run"
    assert cli("run", cfg, "--out", out).exit_code == 0
    damage(out)
    r = cli("run", cfg, "--out", out)
    assert r.exit_code == 0, r.output
    line = next(ln for ln in r.output.splitlines() if ln.startswith("mesh "))
    assert message in line and line.endswith("rerunning"), r.output
    assert "mesh         done" in r.output and "input        up to date" in r.output
    assert cli("inspect", "--check", out / "mesh.h5").exit_code == 0
    assert "mesh         up to date" in cli("run", cfg, "--out", out).output


# -- 4. --from / --to: unknown names, stages not run, --from after --to -------------------------


@pytest.mark.parametrize("args, message", [
    (["--from", "mesh", "--to", "input"], "--from mesh comes after --to input: the stages run in the order input, mesh"),
    (["--to", "meshh"], "--to meshh: unknown stage; the stages are phantom, segment, skeletonize, trace, mesh, simulate, post"),
    (["--from", "simulate"], "--from simulate: not part of this config's run, this config runs the stages input, mesh"),
])
def test_from_to_errors(tmp_path, args, message):
    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    line = one_line_error(cli("run", cfg, "--out", tmp_path / "run", *args))
    assert message in line, line
    assert "ValueError" not in line


def test_from_to_slice_still_works(tmp_path):
    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    r = cli("run", cfg, "--out", tmp_path / "run", "--from", "input", "--to", "input")
    assert r.exit_code == 0 and "input        done" in r.output and "mesh" not in r.output, r.output
    r = cli("run", cfg, "--out", tmp_path / "run", "--from", "mesh", "--to", "mesh")
    assert r.exit_code == 0 and "mesh         done" in r.output and "input " not in r.output, r.output


# -- 5. an output folder that cannot be written is refused up front ------------------------------


def test_impossible_output_folder(tmp_path):
    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    (tmp_path / "afile").write_text("x")
    bad = tmp_path / "afile" / "run"
    line = one_line_error(cli("run", cfg, "--out", bad))
    assert f"output folder {bad} is not writable: Not a directory" in line, line
    line = one_line_error(cli("phantom", "--out", bad))
    assert f"output folder {bad} is not writable" in line, line
    # compare reads its runs first (tests/post/test_post.py checks its output folder with a real run)
    line = one_line_error(cli("compare", tmp_path, "--out", tmp_path / "cmp"))
    assert f"{tmp_path} has no simulation.h5: run it first" in line, line
    assert not (tmp_path / "cmp").exists()
    if Path("/proc/self").exists():
        line = one_line_error(cli("run", cfg, "--out", "/proc/fpx"))
        assert "output folder /proc/fpx is not writable: No such file or directory; choose another --out" in line, line


def test_read_only_output_folder(tmp_path, monkeypatch):
    """A folder the user may not write to (simulated: the tests may run as root, who may)."""
    import fiberpipe.artifacts as P

    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    out = tmp_path / "ro"
    out.mkdir()

    def refuse(*a, **kw):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(P.tempfile, "mkstemp", refuse)
    line = one_line_error(cli("run", cfg, "--out", out))
    assert f"output folder {out} is not writable: Permission denied" in line, line
    assert list(out.iterdir()) == []


# -- 6. an interrupted --force rerun resumes with the command its message gives -------------------

# the reliability tests' small scene, three fibers, with fiber–fiber contact and friction, pressed by
# 4 µm (54 k steps, a checkpoint every 5000; the fibers touch from the start: 14 contacts, friction work > 0)
SMALL = small_scene(effects=["gravity", "damping", "contact", "friction", "plates", "walls"],
                    damping={"alpha": "1e4 1/s"}, contact={"law": "hertz_oriented"}, friction={"mu": 0.2},
                    loading={"displacement": "0.004 mm", "velocity": "60 mm/min", "ramp": "smooth"})
SMALL["input"]["polylines"] = SMALL["input"]["polylines"][:3]
SMALL["solver"]["output_frames"] = 4


def _datasets(path: Path) -> dict:
    import h5py

    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset) else None)
    return out


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    return run_small(tmp_path_factory.mktemp("small"), SMALL)


def test_interrupted_force_rerun_resumes(tmp_path, small_run, monkeypatch):
    import signal
    from contextlib import contextmanager

    import numpy as np

    import fiberpipe.stages.simulate as S

    cfg, ref = small_run
    run = tmp_path / "run"
    shutil.copytree(ref, run)
    polls = {"n": 0}

    @contextmanager
    def ctrl_c_soon():  # a Ctrl-C after two chunks, as the signal handler reports it
        def stop():
            polls["n"] += 1
            return signal.SIGINT if polls["n"] == 3 else None
        yield stop

    monkeypatch.setattr(S, "stop_on_signals", ctrl_c_soon)
    r = cli("simulate", cfg, "--out", run, "--force")
    assert r.exit_code == 130, r.output
    line = one_line_error(r)
    resume = f"fiberpipe simulate {cfg} --out {run} --resume"
    assert resume in line, line
    ck = run / "simulation.checkpoint.h5"
    assert ck.exists() and (run / "simulation.h5").exists()  # the earlier result is kept
    monkeypatch.undo()
    r = cli(*resume.split()[1:])
    assert r.exit_code == 0, r.output
    assert "up to date" not in r.output and "resuming from checkpoint" in r.output, r.output
    assert not ck.exists()
    a, b = _datasets(ref / "simulation.h5"), _datasets(run / "simulation.h5")
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)
    assert "simulate     up to date" in cli("run", cfg, "--out", run, "--to", "simulate").output


def test_run_picks_up_the_checkpoint_of_an_interrupted_force_rerun(tmp_path, small_run, monkeypatch):
    import signal
    from contextlib import contextmanager

    import fiberpipe.stages.simulate as S

    cfg, ref = small_run
    run = tmp_path / "run"
    shutil.copytree(ref, run)

    @contextmanager
    def ctrl_c_now():
        yield lambda: signal.SIGINT

    monkeypatch.setattr(S, "stop_on_signals", ctrl_c_now)
    assert cli("run", cfg, "--out", run, "--from", "simulate", "--to", "simulate", "--force").exit_code == 130
    monkeypatch.undo()
    assert (run / "simulation.checkpoint.h5").exists()
    r = cli("run", cfg, "--out", run, "--to", "simulate")
    assert r.exit_code == 0 and "resuming from checkpoint" in r.output, r.output
    assert not (run / "simulation.checkpoint.h5").exists()


# -- 7. the effects the config lists are the effects recorded (friction included) -----------------


def test_recorded_effects_are_the_configs(tmp_path, small_run):
    import h5py

    cfg, ref = small_run
    asked = SMALL["scene"]["effects"]
    with h5py.File(ref / "simulation.h5", "r") as f:
        assert json.loads(f.attrs["effects"]) == asked
    assert json.loads((ref / "summary.json").read_text())["stages"]["simulate"]["effects"] == asked
    run = tmp_path / "run"
    shutil.copytree(ref, run)
    r = cli("post", cfg, "--out", run)
    assert r.exit_code == 0, r.output
    summary = json.loads((run / "post" / "summary.json").read_text())
    assert summary["effects"] == asked, summary.get("effects")
    assert ", ".join(asked) in (run / "post" / "report.md").read_text()


# -- 8. `inspect ... | head`: a closed pipe ends quietly -----------------------------------------


def test_broken_pipe_exits_quietly(tmp_path):
    import os
    import subprocess
    import sys

    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    assert cli("run", cfg, "--out", tmp_path / "run").exit_code == 0
    r, w = os.pipe()
    os.close(r)  # the reader (head) has gone before the first line is written
    try:
        proc = subprocess.run([sys.executable, "-m", "fiberpipe.cli", "inspect", str(tmp_path / "run" / "mesh.h5")],
                              stdout=w, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(w)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""


# -- 9. a missing input file is the user's, not an earlier stage's -------------------------------


@pytest.mark.parametrize("inp, key, name", [
    ({"volume": "missing.tif", "voxel_size": "15 um"}, "input.volume", "missing.tif"),
    ({"fibers": "nofibers.h5"}, "input.fibers", "nofibers.h5"),
])
def test_missing_input_file_names_the_key(tmp_path, inp, key, name):
    cfg = write_cfg(tmp_path / "c.yaml", {"name": "x", "input": inp, "fiber": {"radius": "0.25 mm"}})
    out = tmp_path / "run"
    line = one_line_error(cli("run", cfg, "--out", out))
    assert line.startswith(f"error: {key}: file {tmp_path / name} does not exist"), line
    assert "earlier stages" not in line
    assert not out.exists()  # nothing ran, no folder made


def test_missing_stage_output_names_the_stage_to_run(tmp_path):
    cfg = write_cfg(tmp_path / "tip.yaml", TIP)
    out = tmp_path / "run"
    line = one_line_error(cli("mesh", cfg, "--out", out))
    assert f"stage mesh needs fibers at {out / 'fibers.h5'}, which does not exist" in line, line
    assert f"run `fiberpipe run {cfg} --out {out} --to input` first" in line, line


# -- 10. skeletonize runs unless skeletonize.enabled: false (a run folder has skeleton.h5) --------


@pytest.mark.parametrize("extra, runs_skeleton", [
    ({}, True),
    ({"trace": {"method": "slices"}}, True),
    ({"trace": {"method": "skeleton"}}, True),
    ({"skeletonize": {"enabled": True}}, True),
    ({"skeletonize": {"enabled": False}}, False),
])
def test_skeletonize_runs_unless_switched_off(extra, runs_skeleton):
    from fiberpipe.config import validate_config
    from fiberpipe.pipeline import planned_stages

    cfg = validate_config({"name": "v", "input": {"phantom": {"n_fibers": 2}}, **extra})
    plan = planned_stages(cfg)
    assert ("skeletonize" in plan) == runs_skeleton, plan
    assert plan[:2] == ["phantom", "segment"] and "trace" in plan


def test_quickstart_runs_every_stage_and_a_switched_off_skeletonize_says_so(tmp_path):
    from fiberpipe.config import load_config
    from fiberpipe.pipeline import planned_stages

    quickstart = Path(__file__).resolve().parents[1] / "configs" / "quickstart.yaml"
    plan = planned_stages(load_config(quickstart))
    assert plan == ["segment", "skeletonize", "trace", "mesh", "simulate", "post"]
    off = write_cfg(tmp_path / "off.yaml", {"extends": str(quickstart), "skeletonize": {"enabled": False}})
    r = cli("skeletonize", off, "--out", tmp_path / "run")
    assert "set skeletonize.enabled: true" in one_line_error(r)


# -- 11. README: the tracing-accuracy example works as written in a fresh folder ------------------


def test_readme_trace_example_works_as_written(tmp_path, monkeypatch):
    import shlex
    import subprocess

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = readme.split("## Using it", 1)[1].split("```sh", 1)[1].split("```", 1)[0]
    lines = [ln.split("  #", 1)[0].strip() for ln in block.splitlines()]
    first = next(i for i, ln in enumerate(lines) if ln.startswith(".venv/bin/fiberpipe phantom --out ph "))
    last = next(i for i, ln in enumerate(lines) if "--truth ph/truth.h5" in ln)
    monkeypatch.chdir(tmp_path)
    for ln in lines[first : last + 1]:
        if ln.startswith(".venv/bin/fiberpipe "):
            r = cli(*shlex.split(ln)[1:])
            assert r.exit_code == 0, (ln, r.output)
        else:
            subprocess.run(ln, shell=True, check=True, cwd=tmp_path)
    assert "recall" in r.output and "f1" in r.output and "matches" not in r.output, r.output
    acc = json.loads((tmp_path / "runs" / "ph" / "trace_accuracy.json").read_text())
    assert acc["n_true"] == 40 and acc["recall"] > 0.9


def test_outputs_problem_reports_any_read_error(tmp_path, monkeypatch):
    """h5py raises RuntimeError (not OSError) on a damaged object header: still 'unreadable', never
    a traceback out of the up-to-date check."""
    import fiberpipe.artifacts as A
    from fiberpipe.pipeline import STAGES, outputs_problem

    def damaged(*a, **kw):
        raise RuntimeError("Unable to synchronously open object (bad object header version number)")

    monkeypatch.setattr(A, "open_checked", damaged)
    (tmp_path / "mesh.h5").write_bytes(b"x")
    stage = STAGES["mesh"]
    why = outputs_problem(stage, [tmp_path / "mesh.h5"])
    assert why is not None and "is unreadable (RuntimeError" in why


# -- a stage stopped while it writes, outputs removed by hand, state files damaged ---------------


def test_a_simulate_stopped_while_writing_is_not_up_to_date_after(tmp_path, small_run, monkeypatch):
    """simulation.h5 is written before the frames: a simulate stopped between them (a full disk, a
    Ctrl-C) left a new simulation.h5 beside the old frames under the old key, and the next run of the
    old config took that mixture as up to date. The key goes before the stage writes."""
    import copy

    import numpy as np

    import fiberpipe.stages.simulate as S

    cfg, ref = small_run
    run = tmp_path / "run"
    shutil.copytree(ref, run)
    other = copy.deepcopy(SMALL)
    other["solver"]["output_frames"] = 3
    other_cfg = write_cfg(tmp_path / "other.yaml", other)

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(S, "write_frames_vtk", disk_full)
    assert "No space left on device" in one_line_error(cli("run", other_cfg, "--out", run))
    assert "simulate: stopped: OSError" in (run / "run.log").read_text()
    monkeypatch.undo()
    r = cli("run", cfg, "--out", run)
    assert r.exit_code == 0 and "simulate     done" in r.output, r.output
    a, b = _datasets(ref / "simulation.h5"), _datasets(run / "simulation.h5")
    assert a["frames/positions"].shape == b["frames/positions"].shape
    assert np.array_equal(a["frames/positions"], b["frames/positions"])


@pytest.mark.parametrize("remove, stage, said", [
    (lambda run: (run / "frames" / "frame_00001.vtu").unlink(), "simulate", "frame_00001.vtu is missing (1 of the 4"),
    (lambda run: (run / "simulation.pvd").unlink(), "simulate", None),  # a missing output: rerun at once
    (lambda run: (run / "post" / "report.md").unlink(), "post", "report.md is missing"),
])
def test_outputs_removed_by_hand_are_made_again(tmp_path, small_run, remove, stage, said):
    """A frame, the ParaView collection or a file post's summary lists, removed: the stage that
    makes it is not up to date (only the stages' main artifacts were checked)."""
    cfg, ref = small_run
    run = tmp_path / "run"
    shutil.copytree(ref, run)
    assert cli("run", cfg, "--out", run).exit_code == 0  # post too
    remove(run)
    r = cli("run", cfg, "--out", run)
    assert r.exit_code == 0 and f"{stage:12s} done" in r.output, r.output
    if said:
        line = next(ln for ln in r.output.splitlines() if ln.startswith(f"{stage:12s} output"))
        assert said in line and line.endswith("rerunning"), r.output
    assert "up to date" in cli("run", cfg, "--out", run).output


@pytest.mark.parametrize("name, text", [("fiberpipe.lock.json", "[1, 2]"), ("fiberpipe.lock.json", '{"simulate": 5}'),
                                        ("fiberpipe.lock.json", '{"simulate": {"key'), ("summary.json", "[]")])
def test_a_damaged_lock_or_summary_is_ignored_with_a_warning(tmp_path, small_run, name, text):
    cfg, ref = small_run
    run = tmp_path / "run"
    shutil.copytree(ref, run)
    (run / name).write_text(text)
    r = cli("run", cfg, "--out", run, "--to", "simulate")
    assert r.exit_code == 0 and "Traceback" not in r.output, r.output
    if name == "summary.json" or text.startswith("[") or "key" in text:
        assert f"warning: {run / name} is " in r.output and "ignored" in r.output, r.output
    assert "up to date" in cli("run", cfg, "--out", run, "--to", "simulate").output


def test_from_a_later_stage_warns_when_the_earlier_outputs_are_stale(tmp_path, small_run):
    """--from simulate with another mesh section: the mesh.h5 it reads was made with other settings;
    the run says so instead of using it in silence."""
    import copy

    cfg, ref = small_run
    run = tmp_path / "run"
    shutil.copytree(ref, run)
    other = copy.deepcopy(SMALL)
    other["mesh"]["element_length"] = "0.6 mm"
    r = cli("run", write_cfg(tmp_path / "other.yaml", other), "--out", run, "--from", "simulate", "--to", "simulate")
    assert r.exit_code == 0 and "warning: mesh's outputs in" in r.output and "run from mesh" in r.output, r.output
    assert "warning" not in cli("run", cfg, "--out", run, "--from", "simulate", "--to", "simulate").output


def test_sigterm_outside_the_step_loop_cleans_up_and_exits_143(tmp_path, monkeypatch):
    """SIGTERM while a stage writes (the solver's step loop checkpoints on it; elsewhere it killed
    the process and left the half-written temporary file): 'terminated', exit 143, no temporary
    file, the stage not recorded as done."""
    import os
    import signal

    import fiberpipe.stages.mesh as M
    from fiberpipe.artifacts import atomic_path

    def killed_while_writing(path, *args, **kwargs):
        with atomic_path(path) as tmp:
            tmp.write_bytes(b"half")
            os.kill(os.getpid(), signal.SIGTERM)
            tmp.write_bytes(b"half a mesh")  # not reached

    monkeypatch.setattr(M, "write_mesh", killed_while_writing)
    handler = signal.getsignal(signal.SIGTERM)
    run = tmp_path / "run"
    r = cli("run", write_cfg(tmp_path / "tip.yaml", TIP), "--out", run)
    assert r.exit_code == 143 and "terminated" in r.output, r.output
    assert not [p for p in run.rglob("*") if p.name.endswith(".tmp") or ".tmp" in p.name]
    assert not (run / "mesh.h5").exists()
    assert "mesh" not in json.loads((run / "fiberpipe.lock.json").read_text())
    assert signal.getsignal(signal.SIGTERM) is handler  # restored for the next command
