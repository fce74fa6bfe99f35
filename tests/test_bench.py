"""``fiberpipe bench`` needs nothing from the source checkout: its benchmarks are modules of the
package and the paper-40 scene ships with it (a copy that must equal configs/paper-40.yaml); the
developer's scripts live in the checkout's ``benchmarks/`` folder, outside the package."""

from pathlib import Path
from types import SimpleNamespace

import yaml

import fiberpipe.bench as bench
from fiberpipe.config import load_config

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "fiberpipe" / "benchmarks" / "data"


def test_every_part_is_a_package_module():
    for name in ("bench_solver", "bench_contact", "bench_pyelastica", "bench_imaging", "bench_threads"):
        mod = bench._load(name)
        assert mod.__name__ == f"fiberpipe.benchmarks.{name}"
        assert Path(mod.__file__).resolve().parent == DATA.parent


def test_the_package_holds_no_developer_script_and_imports_no_test_or_verification_code():
    """A/B runs, profiles and one-off studies are scripts of the checkout's ``benchmarks/`` folder;
    the package's benchmarks build their scenes through the package's public paths."""
    import ast

    for script in ("bench_ab", "ab_worker", "bench_inprocess", "perf_profile", "bench_profile", "paper40_states",
                   "bench_stable_step", "bench_step_energy", "bench_three_beam_energy", "bench_bundle_cost",
                   "bench_fast_ensemble", "bench_effects", "bench_contact_variants"):
        assert not (DATA.parent / f"{script}.py").exists(), script
        assert (ROOT / "benchmarks" / f"{script}.py").is_file(), script
    # the package's benchmarks use no verification code; the scripts only its public scenes
    forbidden = {DATA.parent: ("tests", "_scenes", "fiberpipe.verification", "..verification"),
                 ROOT / "benchmarks": ("tests", "_scenes", "fiberpipe.verification.case_config",
                                       "fiberpipe.verification.contact_cases", "fiberpipe.verification.cases")}
    for folder, prefixes in forbidden.items():
        for path in folder.glob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom):
                    names = ["." * node.level + (node.module or "")]
                elif isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                else:
                    continue
                for name in names:
                    assert not name.startswith(prefixes), f"{path.name} imports {name}"


def test_packaged_paper40_scene_equals_the_shipped_one():
    ours = yaml.safe_load((DATA / "paper-40.yaml").read_text())
    shipped = yaml.safe_load((ROOT / "configs" / "paper-40.yaml").read_text())
    for cfg in (ours, shipped):
        cfg["input"].pop("fibers")
        cfg["post"].pop("reference_fibers")
    assert ours == shipped, "fiberpipe/benchmarks/data/paper-40.yaml differs from configs/paper-40.yaml"
    assert (DATA / "paper-40-fibers.h5").read_bytes() == (ROOT / "data-samples" / "paper-40" / "fibers.h5").read_bytes(), \
        "fiberpipe/benchmarks/data/paper-40-fibers.h5 differs from data-samples/paper-40/fibers.h5"


def test_outside_a_checkout_bench_uses_the_packaged_scene_and_the_working_folder(monkeypatch, tmp_path):
    monkeypatch.setattr(bench, "CHECKOUT", False)
    monkeypatch.chdir(tmp_path)
    assert bench.default_page() == Path("benchmarks.md")
    cfg_path = bench.default_paper40_config()
    assert cfg_path == DATA / "paper-40.yaml"
    cfg = load_config(cfg_path)
    assert Path(cfg.input.fibers).exists()
    mesh = bench.config_mesh(cfg)
    assert mesh.n_fibers == 40


def test_a_part_runs_outside_the_checkout(monkeypatch, tmp_path):
    """The page is written in the working folder, between the markers, with nothing but the package."""
    monkeypatch.setattr(bench, "CHECKOUT", False)
    monkeypatch.chdir(tmp_path)
    calls = []
    fake = SimpleNamespace(main=lambda argv: calls.append(argv) or [],
                           table_lines=lambda rows: ["| gap | law |", "|---|---|"])
    monkeypatch.setattr(bench, "_load", lambda name: fake)
    bench.run_bench(skip=("solver", "pyelastica", "paper40", "imaging", "threads"), echo=lambda *_: None)
    text = (tmp_path / "benchmarks.md").read_text()
    assert bench.BEGIN in text and bench.END in text and "### Contact pass" in text
    assert "| gap | law |" in text and "### Threads" not in text
    assert calls == [["--repeats", "100"]]


def test_window_means_average_the_loading_branch_per_window():
    import numpy as np

    U = np.linspace(0.0, 1e-3, 101)
    assert np.allclose(bench.window_means(U, 2.0 * U, np.array([0.0, 0.5e-3, 1.0e-3])), [0.49e-3, 1.49e-3], rtol=0.02)
