"""Numba cache freshness for the solver's kernels: a cached kernel is valid only for the exact sources
of *every* module of ``fiberpipe/solver``.

numba stamps a cached function with the hash of its own source file only. A cached kernel calls
kernels of other modules (the step loop calls the beam forces and the contact pass, the contact pass
calls the laws...), whose machine code is linked into the cache entry, so editing ``contact.py``
would leave the step loop running the old contact code from the cache. This module registers a
cache locator, tried before numba's own ones, for the functions defined in this package: same cache
directory as numba would choose, but the source stamp is the SHA-256 of all ``*.py`` files of the
package (plus numba's stamp of the function's own file). Any edit anywhere in the solver therefore
invalidates every solver cache entry: stale code cannot run.

Imported by ``fiberpipe/solver/__init__.py`` before any kernel module, so every ``@njit(cache=True)``
of the package is covered (a package submodule import always runs the package ``__init__`` first).
"""

from __future__ import annotations

import functools
import hashlib
import os
import pickle

_PKG_DIR = os.path.dirname(os.path.abspath(__file__))


@functools.lru_cache(maxsize=None)
def _digest(key) -> str:
    h = hashlib.sha256()
    for name, _mt, _sz in key:
        h.update(name.encode())
        with open(os.path.join(_PKG_DIR, name), "rb") as fh:
            h.update(fh.read())
    return h.hexdigest()


# modules outside the solver package compiled into the solver's cached kernels: the LLVM options of
# fiberpipe/_vectorise.py, the kernels of _prefetch.py and _tasks.py
_SHARED = tuple(os.path.join(os.pardir, name) for name in ("_vectorise.py", "_prefetch.py", "_tasks.py"))


def _solver_sources() -> list[str]:
    """The solver package's ``*.py`` files, relative to it (subpackages such as ``terms`` included)."""
    out = []
    for folder, dirs, files in os.walk(_PKG_DIR):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        rel = os.path.relpath(folder, _PKG_DIR)
        out += [name if rel == "." else os.path.join(rel, name) for name in sorted(files) if name.endswith(".py")]
    return out


def package_source_digest() -> str:
    """SHA-256 of the sources of all modules of ``fiberpipe.solver`` (its subpackages included) and of
    the modules in ``_SHARED`` (``fiberpipe/_vectorise.py``, ``_prefetch.py``, ``_tasks.py``; re-hashed
    when one changes)."""
    key = []
    for name in _solver_sources() + list(_SHARED):
        st = os.stat(os.path.join(_PKG_DIR, name))
        key.append((name, st.st_mtime_ns, st.st_size))
    return _digest(tuple(key))


def _install() -> bool:
    try:
        from numba.core import caching
    except Exception:  # pragma: no cover - numba without the caching module
        return False
    base = getattr(caching, "_CacheLocator", None)
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)  # numba ≥ 0.61 / older
    if base is None or impl is None or not hasattr(impl, "_locator_classes"):  # pragma: no cover
        return False
    # one locator per copy of the package (a process may hold two, as the in-process benchmark
    # does: each covers the files of its own folder)
    if any(getattr(c, "_fiberpipe_solver_dir", None) == _PKG_DIR for c in impl._locator_classes):
        return True

    class SolverPackageLocator(base):
        """Numba's own locator for the file, with the whole package's source digest as stamp."""

        _fiberpipe_solver_dir = _PKG_DIR

        def __init__(self, inner):
            self._inner = inner

        def ensure_cache_path(self):
            return self._inner.ensure_cache_path()

        def get_cache_path(self):
            return self._inner.get_cache_path()

        def get_source_stamp(self):
            return (self._inner.get_source_stamp(), package_source_digest())

        def get_disambiguator(self):
            return self._inner.get_disambiguator()

        @property
        def _py_file(self):  # numba's warning that a function cannot be cached names the file
            return self._inner._py_file

        @classmethod
        def from_function(cls, py_func, py_file):
            if not os.path.abspath(py_file).startswith(_PKG_DIR + os.sep):
                return None
            for other in impl._locator_classes:
                if other is cls:
                    continue
                inner = other.from_function(py_func, py_file)
                if inner is not None:
                    return cls(inner)
            return None

    impl._locator_classes.insert(0, SolverPackageLocator)
    _tolerate_stale_index(caching)
    return True


def _tolerate_stale_index(caching) -> None:
    """Read an index that cannot be unpickled as an empty (stale) one. numba unpickles an index's
    overloads before it compares the source stamp, so an index written by an older version of the
    package, whose signatures name a structure the package no longer defines, raises instead of
    being recompiled."""
    cls = getattr(caching, "IndexDataCacheFile", None)
    load = getattr(cls, "_load_index", None)
    if load is None or getattr(load, "_fiberpipe_tolerant", False):  # pragma: no cover
        return

    @functools.wraps(load)
    def _load_index(self):
        try:
            return load(self)
        except (AttributeError, ImportError, EOFError, pickle.UnpicklingError):
            return {}

    _load_index._fiberpipe_tolerant = True
    cls._load_index = _load_index


INSTALLED = _install()
if not INSTALLED:  # pragma: no cover - a numba whose caching internals moved: fail loudly, not stale
    raise ImportError("fiberpipe.solver._jitcache: cannot register the solver's numba cache locator with this "
                      "numba version (numba.core.caching changed); pin numba or update _jitcache.py")
