"""A software prefetch for numba kernels (a leaf module): ``prefetch_row(a, i)`` asks the CPU to bring
the cache line of ``a[i, 0]`` (or ``a[i]``) towards the core, and does nothing else (LLVM's
``llvm.prefetch``; a hint: it neither faults nor changes a result).

The potential contact pass (``solver.contact_potential``) visits its pairs in list order and reads
the positions of each pair's nodes, which lie anywhere in the node arrays; a pair's evaluation is
long enough that the CPU's out-of-order window does not reach the next pair's loads, so each pair
would wait for its own misses. Asking for the nodes of the pairs a few places ahead overlaps those waits with the work.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def prefetch_row(typingctx, arr, idx):
    """Prefetch (read, keep in all levels) the cache line holding ``arr[idx, 0, ...]``."""
    if not isinstance(arr, types.Array) or not isinstance(idx, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        aryty = sig.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        zero = context.get_constant(types.intp, 0)
        index = context.cast(builder, args[1], sig.args[1], types.intp)
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [index] + [zero] * (aryty.ndim - 1),
                                       wraparound=False)
        i32 = ir.IntType(32)
        byte_ptr = ir.IntType(8).as_pointer()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [byte_ptr, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        builder.call(fn, [builder.bitcast(ptr, byte_ptr), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(arr, idx), codegen
