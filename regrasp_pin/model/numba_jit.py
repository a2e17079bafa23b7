"""Compiling plain-Python kernels with numba, for the optional compiled loops
(:mod:`.ik_numba`, :mod:`.capsules_numba`)."""

from __future__ import annotations

import types
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["compile_together"]


def compile_together(
    helpers: Sequence[Callable[..., Any]], kernels: Sequence[Callable[..., Any]]
) -> dict[str, Callable[..., Any]] | None:
    """The ``kernels`` compiled with numba (cached on disk, releasing the GIL), by name,
    each calling the compiled versions of the others and of the ``helpers`` (inlined)
    in one namespace, the kernels' module's (with the names a helper of another module
    reads in its own, such as its constants); None when numba is not installed. The
    functions must come in the order in which they call each other (callees first)."""
    try:
        import numba
    except ImportError:
        return None
    glb = dict(kernels[0].__globals__)
    for f in helpers:  # what a helper of another module reads there (its constants)
        for name, value in f.__globals__.items():
            glb.setdefault(name, value)
    for f in (*helpers, *kernels):
        if f in kernels:
            jit = numba.njit(cache=True, nogil=True, inline="never")
        else:
            jit = numba.njit(cache=True, nogil=True, inline="always")
        glb[f.__name__] = jit(types.FunctionType(f.__code__, glb, f.__name__))
    return {f.__name__: glb[f.__name__] for f in kernels}
