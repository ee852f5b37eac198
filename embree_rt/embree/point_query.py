"""Embree 4's point query (``rtcPointQuery``) for compiled code: its structs, its context and one
query call taking a compiled callback.

``rtcPointQuery`` walks the BVH from a point outwards and calls a callback (here a numba
``@cfunc``) for every primitive in a leaf whose box meets the query's sphere; the callback
computes the distance itself and may *shrink* the sphere's radius (never grow it) so that the
walk skips what can no longer be nearer. Embree knows nothing about distances: whatever the
query finds is in the callback's own state, reached through the ``userPtr`` Embree passes on.

Layouts (Embree 4 headers, this build: ``RTC_MAX_INSTANCE_LEVEL_COUNT`` 1 and instance arrays;
proved by tests/test_point_query_layout.py):

- ``RTCPointQuery`` (rtcore_common.h), 16-byte aligned: {x, y, z, time, radius} float32, in that
  order (the man page lists radius before time; the header and Embree's ``PointQueryK<1>`` put
  time first). Embree ignores a query whose point exceeds ``FLT_LARGE`` (1.8e18) in any
  coordinate or whose radius is negative.
- ``RTCPointQueryContext``, 16-byte aligned: {world2inst float[1][16] @0, inst2world float[1][16]
  @64, instID u32[1] @128, instPrimID u32[1] @132, instStackSize u32 @136}: 144 bytes.
  ``rtcInitPointQueryContext`` (an inline function, so not in the library) sets the stack size
  to 0 and the ids to ``RTC_INVALID_GEOMETRY_ID``.
- ``RTCPointQueryFunctionArguments``: {query* @0, userPtr @8, primID u32 @16, geomID u32 @20,
  context* @24, similarityScale f32 @32}. The callback returns C ``bool``: true when it changed
  the radius, so that Embree refreshes its traversal state.
"""

from __future__ import annotations

import llvmlite.binding as llvm
import numpy as np
from numba import njit, types

from embree_rt.embree import library

# RTCPointQuery, in 4-byte words
QUERY_X = 0
QUERY_Y = 1
QUERY_Z = 2
QUERY_TIME = 3
QUERY_RADIUS = 4
QUERY_WORDS = 8  # 20 bytes, padded to the 16-byte alignment

# RTCPointQueryContext, in 4-byte words
CONTEXT_WORLD_TO_INSTANCE = 0
CONTEXT_INSTANCE_TO_WORLD = 16
CONTEXT_INSTANCE_ID = 32
CONTEXT_INSTANCE_PRIM_ID = 33
CONTEXT_STACK_SIZE = 34
CONTEXT_WORDS = 36  # 140 bytes, padded to 144

# RTCPointQueryFunctionArguments, in 8-byte words (primID and geomID share word 2)
ARGS_QUERY = 0
ARGS_USER = 1
ARGS_IDS = 2  # primID | geomID << 32
ARGS_CONTEXT = 3
ARGS_SIMILARITY = 4  # float32 in the low half
ARGS_WORDS = 5

ALIGN_WORDS = 4  # 16 bytes
# One query's scratch: the query, the context, and slack to align them.
SCRATCH_WORDS = QUERY_WORDS + CONTEXT_WORDS + ALIGN_WORDS

# A query point beyond this in any coordinate is ignored by Embree (FLT_LARGE, common/math).
LARGEST_COORDINATE = 1.844e18

# The callback's C signature: bool(RTCPointQueryFunctionArguments*); C's bool is one byte.
CALLBACK_SIGNATURE = types.uint8(types.uintp)

_NAME = "rtcPointQuery"


def register_symbols() -> None:
    """Tell LLVM where ``rtcPointQuery`` lives in this process (before a kernel calling it is
    compiled or loaded from numba's cache)."""
    llvm.add_symbol(_NAME, library.function_address(_NAME))


# bool rtcPointQuery(scene, RTCPointQuery*, RTCPointQueryContext*, callback, userPtr); the
# returned bool (whether a callback changed the radius) is not needed, so it is not read.
rtc_point_query = types.ExternalFunction(
    _NAME, types.void(types.uintp, types.uintp, types.uintp, types.uintp, types.uintp)
)


@njit(inline="always")
def init_scratch(scratch: np.ndarray) -> int:
    """Initialise a query's scratch, an (SCRATCH_WORDS,) uint32 array, and return the word at
    which its (16-byte aligned) query starts; the context follows the query. The context is
    ``rtcInitPointQueryContext``'s: no instance on the stack."""
    b = ((16 - (scratch.ctypes.data & 15)) & 15) >> 2
    c = b + QUERY_WORDS
    scratch[c + CONTEXT_INSTANCE_ID] = library.INVALID_ID
    scratch[c + CONTEXT_INSTANCE_PRIM_ID] = library.INVALID_ID
    scratch[c + CONTEXT_STACK_SIZE] = 0
    return b


@njit(inline="always")
def point_query(scene, scratch, b, x, y, z, radius, callback, user):
    """One ``rtcPointQuery`` from the float32 point (x, y, z) with ``radius`` (``np.inf``: the
    whole scene) on the committed ``scene``; ``callback`` is the address of a ``@cfunc`` of
    ``CALLBACK_SIGNATURE``, ``user`` the address Embree hands it as ``userPtr``. ``scratch``
    and ``b`` as ``init_scratch`` prepared them (reusable from query to query)."""
    floats = scratch.view(np.float32)
    floats[b + QUERY_X] = x
    floats[b + QUERY_Y] = y
    floats[b + QUERY_Z] = z
    floats[b + QUERY_TIME] = 0.0
    floats[b + QUERY_RADIUS] = radius
    address = scratch.ctypes.data + 4 * b
    rtc_point_query(scene, address, address + 4 * QUERY_WORDS, callback, user)
