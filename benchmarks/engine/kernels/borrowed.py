"""Arrays without their reference count, for the kernels' loops.

numba counts a reference each time a kernel makes a view of an array
(``P_all[run]``, ``scratch[0]``), reads one out of a tuple or passes one to
a called function, and gives it back when the view dies: two atomic
operations on the array's counter. Where two threads do this on views of
the same array (the batch's state, its block, its record), the counter's
cache line goes back and forth between the cores; in a profile of 128
CubeSat MEKF runs a fifth of the process's samples fell on these counts.

:func:`borrowed` gives the same array (the same data, shape and strides)
without its counter: numba skips the count of an array that has none, and of
every view made from it. A borrowed array must not outlive the array it
borrows, which alone keeps the memory: so borrow the kernel's arguments,
which the caller holds until the kernel returns, or arrays the kernel makes
before its loop over the runs and hands to it (the loop holds them until
its last run ends, as the MEKF's ``_batch_scratch``); never an array made
inside a run's iteration, which numba frees after its last use there.
"""
from __future__ import annotations

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


def _without_count(context, builder, typ, value):
    """``value`` of type ``typ`` with every array in it left without its counter."""
    if isinstance(typ, types.Array):
        array = context.make_array(typ)(context, builder, value=value)
        array.meminfo = cgutils.get_null_value(array.meminfo.type)
        array.parent = cgutils.get_null_value(array.parent.type)
        return array._getvalue()
    if isinstance(typ, types.BaseTuple):
        items = [_without_count(context, builder, item_type, builder.extract_value(value, i))
                 for i, item_type in enumerate(typ)]
        return context.make_tuple(builder, typ, items)
    return value


@intrinsic
def borrowed(typingctx, value):
    """``value`` (an array, or a tuple or named tuple of arrays and scalars)
    with every array in it borrowed: views and calls cost no atomic count."""
    def codegen(context, builder, signature, arguments):
        return _without_count(context, builder, signature.args[0], arguments[0])
    return value(value), codegen
