"""Typed pointers from raw addresses, for compiled code that reads Embree's structs.

Embree hands callbacks and buffers over as addresses; ``carray(floats(address), n)`` views the
memory there as an (n,) float32 array, with no copy and no bounds known to NumPy.
"""

from __future__ import annotations

from llvmlite import ir
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
doubles = _pointer_to(types.float64)
ints = _pointer_to(types.int32)


@intrinsic
def prefetch(typingctx, address):
    """Ask the CPU to start loading the cache line at ``address`` (LLVM's ``llvm.prefetch``:
    a read, kept in every cache level); no effect on results, and none at all on an address
    that is not mapped. For loops that gather rows of big tables at scattered places."""

    def codegen(context, builder, signature, args):
        byte_pointer = ir.IntType(8).as_pointer()
        word = ir.IntType(32)
        function_type = ir.FunctionType(ir.VoidType(), [byte_pointer, word, word, word])
        name = "llvm.prefetch.p0"
        function = builder.module.globals.get(name) or ir.Function(
            builder.module, function_type, name=name
        )
        builder.call(
            function,
            [
                builder.inttoptr(args[0], byte_pointer),
                ir.Constant(word, 0),
                ir.Constant(word, 3),
                ir.Constant(word, 1),
            ],
        )
        return context.get_dummy_value()

    return types.void(types.uintp), codegen
