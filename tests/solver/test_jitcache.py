"""The solver's numba cache entries are stamped with the sources of every solver module."""

import pytest

from fiberpipe.solver import _jitcache, _kernels_integrate as K, contact_potential
from fiberpipe.solver.terms import contact as contact_term


def test_solver_kernels_use_the_package_wide_cache_stamp():
    assert _jitcache.INSTALLED
    # a kernel of the solver package and one of its subpackage terms
    for fn in (K.advance_plain, contact_potential.contact_forces_pot, contact_term.contact_step):
        loc = fn._cache._impl._locator
        assert type(loc).__name__ == "SolverPackageLocator"
        assert loc.get_source_stamp()[1] == _jitcache.package_source_digest()


def test_an_index_naming_a_structure_gone_from_the_package_reads_as_stale(tmp_path):
    """An index written by an older version of the package, whose signatures name a class it no
    longer defines, is recompiled instead of raising."""
    import pickle
    import types

    from numba.core import caching

    gone = types.ModuleType("fiberpipe_gone_module")
    exec("class Gone:\n    pass", gone.__dict__)
    gone.Gone.__module__ = "fiberpipe_gone_module"
    import sys
    sys.modules["fiberpipe_gone_module"] = gone
    try:
        data = pickle.dumps((("stamp",), {("sig", gone.Gone()): "entry"}))
    finally:
        del sys.modules["fiberpipe_gone_module"]
    index = tmp_path / "f.nbi"
    cache_file = object.__new__(caching.IndexDataCacheFile)
    cache_file._index_path = str(index)
    cache_file._version = "v"
    cache_file._source_stamp = ("stamp",)
    with open(index, "wb") as fh:
        pickle.dump("v", fh)
        fh.write(data)
    assert cache_file._load_index() == {}


def test_step_loop_specialisations():
    assert K.step_loop_for(()) is K.advance_plain
    kernels, records = [contact_term.contact_step], [K.no_record]
    owner = dict(forces_of=contact_term.contact_forces_of)
    loop = K.step_loop_for(kernels, records, cache_names=["contact"], **owner)
    assert loop is K.step_loop_for(kernels, records, cache_names=["contact"], **owner)
    assert loop._cache._impl is not None  # the built-in contact loop is cached on disk
    # without its force array it is another loop, under another cache name
    bare = K.step_loop_for(kernels, records, cache_names=["contact"])
    assert bare is not loop and bare.py_func.__name__ != loop.py_func.__name__
    # a term without a cache name: compiled per process
    assert type(K.step_loop_for(kernels, records, cache_names=[None], **owner)._cache).__name__ == "NullCache"


def test_threaded_loops_are_separate_and_cached_whole():
    """The prange beam pass is only in the solver.threads > 1 variants and is never cached on its own;
    the threaded loop of a built-in hook is cached whole, under its own name."""
    from fiberpipe.solver import _kernels_beam as B

    assert type(B.beam_pass_fibers._cache).__name__ == "NullCache"
    par = K.step_loop_for((), threads=2)
    assert par is not K.advance_plain and par is K.step_loop_for((), threads=2)
    def body(loop):  # the entry called from Python calls the loop's body (without reference counts)
        return loop.py_func.__globals__["_loop_body"].py_func.__globals__

    assert body(K.advance_plain)["_beam_pass"] is B.beam_pass_all
    assert body(par)["_beam_pass"] is B.beam_pass_fibers
    args = ([contact_term.contact_step], [K.no_record])
    owner = dict(forces_of=contact_term.contact_forces_of)
    loop = K.step_loop_for(*args, threads=2, cache_names=["contact"], **owner)
    assert loop is not K.step_loop_for(*args, cache_names=["contact"], **owner)
    assert loop._cache._impl is not None and loop.py_func.__name__.endswith("_threads")


_PLAIN = """
import numpy as np
from fiberpipe.solver import Damping, Material, SimulationSettings, build_model, simulate
s = np.linspace(0, 1, 11)[:, None]
m = build_model(s * np.array([3e-3, 0, 0]), np.array([0, 11]), 0.25e-3, Material(15e9, 1380.0, 0.3))
print(simulate(m, [Damping(1e5)], SimulationSettings(end_time_s=1e-5, output_frames=2)).completed)
"""
_CONTACT = """
import numpy as np
from fiberpipe.solver import Damping, Material, SimulationSettings, build_model, simulate
from fiberpipe.verification.case_config import contact_hook
s = np.linspace(0, 1, 11)[:, None]
x = np.vstack([s * np.array([3e-3, 0, 0]), s * np.array([3e-3, 0, 0]) + np.array([0, 0, 0.5e-3 - 1e-7])])
m = build_model(x, np.array([0, 11, 22]), 0.25e-3, Material(15e9, 1380.0, 0.3))
print(simulate(m, [Damping(1e5), contact_hook(m)], SimulationSettings(end_time_s=1e-5, output_frames=2)).completed)
"""


@pytest.mark.slow
def test_step_loops_cached_by_different_processes_load_cleanly(tmp_path):
    """Regression: with the prange beam kernel cached and linked into the loops, a loop compiled in
    a second process crashed (SIGSEGV) when a third loaded it. Plain, contact and the threaded
    contact loop (cached whole, its parallel kernels never on their own) compiled and loaded in turn
    by seven processes sharing one fresh cache directory must all succeed."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "NUMBA_NUM_THREADS": "2"}
    threaded = _CONTACT.replace("output_frames=2)", "output_frames=2, threads=2)")
    for name, code in (("plain", _PLAIN), ("contact", _CONTACT), ("threaded", threaded), ("contact", _CONTACT),
                       ("threaded", threaded), ("plain", _PLAIN), ("threaded", threaded)):
        r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=900)
        assert r.returncode == 0 and r.stdout.strip() == "True", (name, r.returncode, r.stderr[-2000:])


def test_package_stamp_covers_the_shared_modules_the_cached_loops_link():
    """A change of fiberpipe/_prefetch.py or _tasks.py (compiled into the contact pass and its
    threaded loop) must recompile the cached loops, as one of the solver's own modules does."""
    import os

    names = {os.path.basename(p) for p in _jitcache._SHARED}
    assert {"_vectorise.py", "_prefetch.py", "_tasks.py"} <= names


def test_package_stamp_covers_the_terms_subpackage():
    """A term's module (``fiberpipe/solver/terms/``) is in the stamp of every cached solver kernel."""
    assert "terms/contact.py" in _jitcache._solver_sources()
    assert "terms/planes.py" in _jitcache._solver_sources()


def test_no_kernel_asks_numba_for_its_threads():
    """numba's ``get_num_threads()`` in a kernel reads a ctypes pointer, a dynamic global: every step
    loop that links the kernel then stays out of numba's cache ("Cannot cache compiled function ...
    as it uses dynamic globals") and compiles again in every run. The passes fix their task counts
    without it (``fiberpipe._tasks``)."""
    import re
    from pathlib import Path

    import fiberpipe

    root = Path(fiberpipe.__file__).parent
    calls = [f"{path.relative_to(root)}:{n}" for path in sorted(root.rglob("*.py"))
             for n, line in enumerate(path.read_text().splitlines(), 1)
             if re.search(r"get_num_threads\s*\(", line.split("#")[0])]
    assert not calls, calls
