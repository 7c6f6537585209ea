"""The per-run path's own plain functions compiled for the kernels, the
functions they call turned to their compiled twins: one definition of
each formula, read by both paths, cannot drift."""
from __future__ import annotations

import types

from numba import njit


def compiled(func, inline: bool = False, **globals_):
    """``func`` compiled (inlined into its callers with ``inline``), the
    globals it calls swapped for compiled twins: ``name=function``, or
    ``name={attribute: function}`` for a module."""
    names = dict(func.__globals__)
    for name, twin in globals_.items():
        if isinstance(twin, dict):
            namespace = types.ModuleType(f"{name}_compiled")
            for attribute, twin_function in twin.items():
                setattr(namespace, attribute, twin_function)
            twin = namespace
        names[name] = twin
    clone = types.FunctionType(func.__code__, names, func.__name__, func.__defaults__,
                               func.__closure__)
    clone.__module__, clone.__qualname__ = func.__module__, func.__qualname__
    return njit(cache=True, error_model="numpy", inline="always" if inline else "never")(clone)
