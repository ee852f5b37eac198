"""Typed pointers from raw addresses, for compiled code that reads Embree's structs.

Embree hands callbacks and buffers over as addresses; ``carray(floats(address), n)`` views the
memory there as an (n,) float32 array, with no copy and no bounds known to NumPy.
"""

from __future__ import annotations

from numba import types
from numba.extending import intrinsic


def _pointer_to(element):
    pointer_type = types.CPointer(element)

    @intrinsic
    def as_pointer(typingctx, address):
        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(pointer_type))

        return pointer_type(types.uintp), codegen

    return as_pointer


words64 = _pointer_to(types.uint64)
words32 = _pointer_to(types.uint32)
floats = _pointer_to(types.float32)
ints = _pointer_to(types.int32)
