"""LLVM's vector code for fiberpipe's numba kernels: loop-vectoriser limits and vector width (a leaf module).

Imported by ``fiberpipe/solver/__init__.py`` and ``fiberpipe/imaging/_kernels.py`` before any of
their kernels compiles or loads from numba's cache; both settings are process-wide.

**Loop-vectoriser limits.** The beam pass and the node update (``solver._kernels_beam.beam_pass_nodes``,
``solver._kernels_integrate.update_range``) read and write some twenty arrays in one loop. numba marks
no argument ``noalias``, so LLVM vectorises such a loop only behind run-time checks that no written
array overlaps another one it touches, and by default it gives up above 8 such checks
(``runtime-memory-check-threshold``) and 16 index-wrap assumptions (``vectorize-scev-check-threshold``).
Raising both lets it emit the vector loop with its checks, once per call (measured on paper-40's
nodes: the two passes run 3× faster); where the arrays do overlap the checks take the scalar loop,
so results are correct either way. The options only make the vectoriser more willing.

**Vector width.** On CPUs with AVX-512, LLVM's tuning for most Intel models prefers 256-bit vectors
(``prefer-256-bit``: older cores lower their clock under 512-bit instructions), so the loops above
run 4 doubles per instruction instead of 8. Unless the user chose numba's target
(``NUMBA_CPU_NAME``, ``NUMBA_CPU_FEATURES``) or ``FIBERPIPE_VECTOR_WIDTH=256``, the host's features
are given to numba with ``-prefer-256-bit``: the beam pass on paper-40 takes 11.7 instead of 28 µs
per call on a 2-core Xeon (docs/benchmarks.md). numba reads the features when its code generator
starts, at the process's first compile or cache load; a process that ran numba code before importing
fiberpipe keeps the width it started with. Kernels cached with one width are compiled again for the
other (numba's cache index holds the CPU features).
"""

from __future__ import annotations

import os

import llvmlite.binding as llvm

_OPTIONS = (
    "--runtime-memory-check-threshold=1000",
    "--vectorize-memory-check-threshold=1000",
    "--vectorize-scev-check-threshold=1000",
)

#: ``FIBERPIPE_VECTOR_WIDTH``: ``512`` (default) lifts LLVM's 256-bit preference on AVX-512 hosts,
#: ``256`` keeps it
WIDTH_ENV = "FIBERPIPE_VECTOR_WIDTH"


def wide_vector_features(host_features: str, environ=os.environ) -> str | None:
    """The CPU feature string to give numba (``host_features`` + ``,-prefer-256-bit``), or None to
    leave numba's own choice: the host has no AVX-512, the user set numba's target, or asked for 256 bits."""
    if environ.get(WIDTH_ENV, "512").strip() == "256":
        return None
    if environ.get("NUMBA_CPU_NAME") or environ.get("NUMBA_CPU_FEATURES"):
        return None
    if "+avx512f" not in host_features.split(","):
        return None
    return host_features + ",-prefer-256-bit"


def _install() -> None:
    for opt in _OPTIONS:
        llvm.set_option("", opt)
    from numba.core import config

    if config.CPU_NAME is None and config.CPU_FEATURES is None:
        features = wide_vector_features(llvm.get_host_cpu_features().flatten())
        if features is not None:
            config.CPU_FEATURES = features


_install()
