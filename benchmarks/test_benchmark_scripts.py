"""The developer scripts' own checks (``make test-benchmarks``; not part of ``make test``): they
run from this folder, where each script imports its siblings by name."""

import importlib
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_curve_window_error_is_the_largest_window_mean_difference():
    """Two curves over 1 s, five windows: ``new`` is ``ref`` + 0.1 N in the third window only, the
    largest reference window mean is 5 N: 2 %."""
    import bench_ab as ba

    t = [(k + 0.5) / 100 for k in range(100)]
    ref = [(tk, float(int(tk * 5) + 1)) for tk in t]
    new = [(tk, f + (0.1 if 0.4 <= tk < 0.6 else 0.0)) for tk, f in ref]
    assert abs(ba.curve_window_error(ref, new, 1.0) - 0.02) < 1e-12


def test_fast_ensemble_gravity_factors_alternate_around_one():
    from bench_fast_ensemble import gravity_factor
    assert [round((gravity_factor(r) - 1.0) * 1e8) for r in range(5)] == [0, 1, -1, 2, -2]


def test_fast_ensemble_setting_parses_numbers_and_unit_strings():
    from bench_fast_ensemble import parse_setting
    name, over = parse_setting("ms100:solver.mass_scaling=100,scene.damping.alpha=1e3 1/s,solver.stable_step=modes")
    assert name == "ms100"
    assert over == {"solver.mass_scaling": 100, "scene.damping.alpha": "1e3 1/s", "solver.stable_step": "modes"}
    assert parse_setting("study:") == ("study", {})


def test_fast_ensemble_error_is_ensemble_mean_against_ensemble_mean(tmp_path):
    import numpy as np

    from bench_fast_ensemble import report

    U = np.linspace(0.0, 1e-3, 101)

    def save(name, F):
        np.savez(tmp_path / f"{name}.npz", U=U, F_cell=F, wall_s=1.0, wall_steady_s=1.0, steps=10, completed=True)

    # two reference runs scattered ±10 % around F = 1 N, two fast runs at 1.05 N: 5 % off the
    # reference ensemble although each fast run is within the reference runs' own scatter
    save("ref_00", np.full_like(U, 1.1))
    save("ref_01", np.full_like(U, 0.9))
    save("fast_00", np.full_like(U, 1.05))
    save("fast_01", np.full_like(U, 1.05))
    table = report(tmp_path, ["ref", "fast"], 0.5e-3)
    rows = {line.split("|")[1].strip(): line.split("|") for line in table.splitlines() if line.startswith("| ref")
            or line.startswith("| fast")}
    assert rows["fast"][6].strip() == "5.00 %"
    assert rows["ref"][6].strip() == "0.00 %"
    assert rows["ref"][7].strip() == "18.18–22.22 %"  # 0.2 / 1.1 and 0.2 / 0.9


def test_fast_ensemble_report_keeps_settings_whose_names_share_a_prefix_apart(tmp_path):
    import numpy as np

    from bench_fast_ensemble import report

    U = np.linspace(0.0, 1e-3, 11)
    for name, f in (("m_00", 1.0), ("m_s1_00", 2.0)):
        np.savez(tmp_path / f"{name}.npz", U=U, F_cell=np.full_like(U, f), wall_s=1.0, wall_steady_s=1.0, steps=10,
                 completed=True)
    rows = [line.split("|") for line in report(tmp_path, ["m", "m_s1"], 0.5e-3).splitlines() if line.startswith("| m")]
    assert [(r[1].strip(), r[2].strip()) for r in rows] == [("m", "1"), ("m_s1", "1")]


def test_fast_ensemble_specimens_runs_the_reference_on_the_first_specimens_only(tmp_path, monkeypatch, capsys):
    """``--config`` twice, ``--reference-specimens 1``: the reference runs on the first specimen, the
    fast setting on both, each in its config's folder name; the fast setting's window means are
    1.0 and 1.2 N on the two specimens, the reference's 1.05 N: |ΔF| 0.05 N = 4.76 % of 1.05 N
    against a spread of sd 0.1414 N (range 0.2 N) over a mean of 1.1 N: 12.86 % (18.18 %)."""
    import numpy as np

    import bench_fast_ensemble as bfe

    U = np.linspace(0.0, 1e-3, 101)
    level = {("ref", "specimen-s0"): 1.05, ("fast", "specimen-s0"): 1.0, ("fast", "specimen-s1"): 1.2}
    calls = []

    def fake_run_one(overrides, run, path, gravity_step, config):
        calls.append((path.stem, config.parent.name))
        F = np.full_like(U, level[(path.stem[:-3], config.parent.name)])
        np.savez(path, U=U, F_cell=F, wall_s=2.0, wall_steady_s=2.0, cpu_s=1.5, steps=10, completed=True)

    monkeypatch.setattr(bfe, "run_one", fake_run_one)
    configs = [str(tmp_path / f"specimen-s{k}" / "config.yaml") for k in (0, 1)]
    bfe.main(["--out", str(tmp_path / "out"), "--runs", "1", "--reference-specimens", "1", "--window-mm", "0.5",
              "--config", configs[0], "--config", configs[1], "--setting", "ref:solver.mass_scaling=1",
              "--setting", "fast:"])
    assert sorted(calls) == [("fast_00", "specimen-s0"), ("fast_00", "specimen-s1"), ("ref_00", "specimen-s0")]
    printed = capsys.readouterr().out
    assert "fast vs ref on specimen-s0: max |ΔF| 0.0500 N = 4.76 % of ref's largest window mean" in printed
    assert "fast over 2 specimens: max sd 12.86 %, max range 18.18 % of its largest mean window mean" in printed
    assert "| fast | specimen-s1 | 10 | 2.0 | 1.5 |" in printed


def test_perf_profile_names_numba_functions_and_groups_samples_per_thread():
    from numba import njit

    from perf_profile import _short_name, aggregate, table, write_perf_map

    assert _short_name("_ZN9fiberpipe6solver17contact_potential11_merge_rowsB4v301B68c8tJTIeFIjx") \
        == "contact_potential._merge_rows"
    assert _short_name("__ieee754_log_fma") == "__ieee754_log_fma"
    report = """
# comment
    40.00%   400  101:python  [JIT] tid 101   [.] _ZN9fiberpipe6solver18_kernels_integrate12update_rangeB4v3
    10.00%   100  101:python  libgomp.so.1.0.0  [.] 0x000000000001f622
    30.00%   300  102:python  libgomp.so.1.0.0  [.] 0x000000000001f7da
    20.00%   200  102:python  [JIT] tid 101   [.] _ZN9fiberpipe6solver13_kernels_beam15beam_pass_nodesB3v48
"""
    per = aggregate(report)
    assert per["101"]["_kernels_integrate.update_range"] == 400
    assert per["102"]["libgomp (OpenMP runtime: waiting, task start)"] == 300
    lines = table(per, 123.4, "101")
    assert lines[0] == "123.4 µs per step (wall)" and lines[2].startswith("main thread: 500 samples")
    assert "| _kernels_integrate.update_range | 80.0 % |" in lines
    assert "| libgomp (OpenMP runtime: waiting, task start) | 60.0 % |" in lines

    @njit(cache=False)
    def twice(x):
        return 2.0 * x

    twice(1.0)
    assert write_perf_map() > 0
    import os

    path = f"/tmp/perf-{os.getpid()}.map"
    try:
        text = open(path).read()
        assert "twice" in text
        start, size, _ = text.splitlines()[0].split(" ", 2)
        assert int(start, 16) > 0 and int(size, 16) > 0
    finally:
        os.unlink(path)


def test_inprocess_mirror_renames_the_package_imports_and_keeps_unchanged_files(tmp_path):
    """bench_inprocess mirrors the reference's package under another name: its imports of
    ``fiberpipe`` read the mirror's name (strings and other names untouched), numba's caches are not
    copied, a file whose text is unchanged keeps its time stamp (numba's cache stays valid) and a
    changed one is rewritten; the mirror imports."""
    from bench_inprocess import MIRROR_NAME, mirror_package

    pkg = tmp_path / "ref" / "fiberpipe"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "__init__.py").write_text("from fiberpipe.sub import a\nimport fiberpipe.sub\nfiberpipe_x = 1\n")
    (pkg / "sub" / "__init__.py").write_text("from . import a\n")
    (pkg / "sub" / "a.py").write_text("NAME = 'fiberpipe'\n")
    (pkg / "table.csv").write_text("k,1\n")
    (pkg / "__pycache__" / "kernel.nbi").write_bytes(b"index")
    root = mirror_package(tmp_path / "ref", tmp_path / "mirror")
    m = root / MIRROR_NAME
    assert (m / "__init__.py").read_text() == f"from {MIRROR_NAME}.sub import a\nimport {MIRROR_NAME}.sub\nfiberpipe_x = 1\n"
    assert (m / "sub" / "a.py").read_text() == "NAME = 'fiberpipe'\n"
    assert (m / "table.csv").is_file() and not (m / "__pycache__").exists()
    for f in (m / "__init__.py", m / "sub" / "a.py"):
        os.utime(f, ns=(10**9, 10**9))
    (pkg / "sub" / "a.py").write_text("NAME = 'changed'\n")
    mirror_package(tmp_path / "ref", tmp_path / "mirror")
    assert (m / "__init__.py").stat().st_mtime_ns == 10**9  # unchanged: kept
    assert (m / "sub" / "a.py").stat().st_mtime_ns != 10**9 and "changed" in (m / "sub" / "a.py").read_text()
    sys.path.insert(0, str(root))
    try:
        assert importlib.import_module(f"{MIRROR_NAME}.sub.a").NAME == "changed"
    finally:
        sys.path.remove(str(root))
        for name in [n for n in sys.modules if n == MIRROR_NAME or n.startswith(MIRROR_NAME + ".")]:
            del sys.modules[name]


def test_inprocess_bench_refuses_a_folder_without_the_package(tmp_path, capsys):
    from bench_inprocess import main

    with pytest.raises(SystemExit) as err:
        main(["--reference", str(tmp_path)])
    assert "no fiberpipe package" in str(err.value)
    with pytest.raises(SystemExit) as err:
        main(["--reference", str(tmp_path), "--state", str(tmp_path / "missing.npz")])
    assert "no such file" in str(err.value)
    bad = tmp_path / "state.npz"
    bad.write_bytes(b"not a numpy file")
    with pytest.raises(SystemExit) as err:
        main(["--reference", str(tmp_path), "--state", str(bad)])
    assert str(err.value).startswith(f"error: {bad}: not a saved state")


def test_inprocess_mirror_imports_nothing_of_this_code_and_keeps_its_own_cache_guard(tmp_path):
    """The mirror of this checkout, imported beside this code, pulls in no ``fiberpipe`` module
    (checked in a process of its own), and each copy of the solver package registers its own numba
    cache locator (the whole package's sources as stamp), so that an edit of either side's solver
    recompiles that side."""
    import subprocess

    from bench_inprocess import MIRROR_NAME, mirror_package

    root = mirror_package(ROOT, tmp_path / "mirror")
    probe = (f"import sys; sys.path.insert(0, {str(root)!r}); import {MIRROR_NAME}.solver, "
             f"{MIRROR_NAME}.benchmarks.scenes, {MIRROR_NAME}.bench; import fiberpipe.solver\n"
             "from numba.core import caching\n"
             "impl = getattr(caching, 'CacheImpl', None) or caching._CacheImpl\n"
             "print(sorted(c._fiberpipe_solver_dir for c in impl._locator_classes if hasattr(c, '_fiberpipe_solver_dir')))\n")
    before = ("import sys; sys.path.insert(0, %r); import %s.solver, %s.benchmarks.scenes, %s.bench; "
              "print(sorted(m for m in sys.modules if m == 'fiberpipe' or m.startswith('fiberpipe.')))"
              % (str(root), MIRROR_NAME, MIRROR_NAME, MIRROR_NAME))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", before], capture_output=True, text=True, cwd=tmp_path, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "[]"
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=tmp_path, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    dirs = eval(r.stdout.strip())
    assert sorted(dirs) == sorted([str(root / MIRROR_NAME / "solver"), str(ROOT / "fiberpipe" / "solver")])
