"""The stop flag as numba kernels read it: :func:`stopped`, an atomic load the compiler keeps in the loop.

A kernel's stop flag (:mod:`terrainvis.core.interrupt`) is set by another thread while the
kernel runs. Read as ``stop[0] != 0``, it is a plain load, and the compiler may assume
that no other thread writes it: in a ``prange`` body, where the loop writes nothing that
could alias the flag, LLVM hoists the load out of the loop, and the kernel never sees the
flag (docs/architecture.md, "Interrupts in long kernels", has the measurement).
:func:`stopped` loads the flag atomically with
monotonic ("relaxed") ordering: on x86-64 the same single move instruction, but one the
compiler must perform every time the code reaches it.

Examples
--------
>>> import numba, numpy as np
>>> @numba.njit
... def first_rows(out, stop):
...     for i in range(out.shape[0]):
...         if stopped(stop):
...             return
...         out[i] = i
>>> out = np.zeros(3)
>>> first_rows(out, np.zeros(1, dtype=np.int64)); out.tolist()
[0.0, 1.0, 2.0]
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from .compiling import install

__all__ = ["stopped"]

# every kernel module imports this one: from here on, a kernel that starts compiling says so
install()


@intrinsic
def stopped(typingctx, stop):
    """True when the stop flag ``stop`` (a (1,) int64 array) is set: ``stop[0] != 0``, read atomically."""
    if not (isinstance(stop, types.Array) and stop.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        flag = context.make_array(signature.args[0])(context, builder, args[0])
        value = builder.load_atomic(flag.data, ordering="monotonic", align=8)
        return builder.icmp_signed("!=", value, ir.Constant(value.type, 0))

    return types.boolean(stop), codegen
