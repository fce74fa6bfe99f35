"""LLVM's loop-vectoriser limits for the step loop's node-wise passes (a leaf module).

The beam pass and the node update (``_kernels_beam.beam_pass_nodes``, ``_kernels_integrate.update_range``)
read and write some twenty arrays in one loop. numba marks no argument ``noalias``, so LLVM vectorises
such a loop only behind run-time checks that no written array overlaps another one it touches, and by
default it gives up above 8 such checks (``runtime-memory-check-threshold``) and 16 index-wrap
assumptions (``vectorize-scev-check-threshold``). Raising both lets it emit the vector loop with its
checks, once per call (measured on paper-40's nodes: the two passes run 3× faster, 8 doubles per AVX-512
instruction); where the arrays do overlap the checks take the scalar loop, so results are correct
either way. The options are process-wide and only make the vectoriser more willing.

Imported by ``fiberpipe/solver/__init__.py`` before any kernel is compiled.
"""

from __future__ import annotations

import llvmlite.binding as llvm

_OPTIONS = (
    "--runtime-memory-check-threshold=1000",
    "--vectorize-memory-check-threshold=1000",
    "--vectorize-scev-check-threshold=1000",
)


def _install() -> None:
    for opt in _OPTIONS:
        llvm.set_option("", opt)


_install()
