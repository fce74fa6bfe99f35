"""Specialising a jitted kernel on the kernels it calls (a leaf module).

numba compiles a call to another jitted function directly (and may inline it) when the callee is a
module global of the caller. To give a kernel another callee without an indirect call, copy the
caller's Python function with that global rebound and jit the copy: this is how the step loop is
specialised on its contact hook, and the contact kernels on a contact law's own force functions.
"""

from __future__ import annotations

import types

from numba import njit


def specialise(template, name: str, bindings: dict, *, cache: bool, **flags):
    """A jitted copy of ``template`` (a plain function or a numba dispatcher) whose module globals
    named in ``bindings`` are replaced; ``flags`` are numba's (``fastmath``, ``inline``...)."""
    py = getattr(template, "py_func", template)
    g = dict(py.__globals__)
    g.update(bindings)
    fn = types.FunctionType(py.__code__, g, name, py.__defaults__, py.__closure__)
    fn.__qualname__ = name
    fn.__module__ = py.__module__
    fn.__doc__ = py.__doc__
    return njit(cache=cache, **flags)(fn)
