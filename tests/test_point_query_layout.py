"""embree/point_query.py's view of Embree 4's point query structs, proved through what Embree hands
a callback: every field of RTCPointQueryFunctionArguments is recorded and checked against what
was passed; the query's radius word is proved by what a radius finds (read from another word,
the answers would differ); the context's world2inst and instStackSize words by the similarity
scale Embree derives from them. (The context's instID/instPrimID words are written as
rtcInitPointQueryContext writes them but never read by a query without instances.)"""

from __future__ import annotations

import numpy as np
from numba import carray, cfunc, njit

from embree_rt.compiled.pointers import doubles, floats, words64
from embree_rt.embree import BVH, point_query

_RECORD = 12  # words recorded per call
_CALLS = 128


@cfunc(point_query.CALLBACK_SIGNATURE, nopython=True)
def _record(address):
    args = carray(words64(address), point_query.ARGS_WORDS)
    user = args[point_query.ARGS_USER]
    log = carray(doubles(user), 1 + _RECORD * _CALLS)
    words = carray(words64(user), 1 + _RECORD * _CALLS)
    k = np.int64(log[0])
    if k < _CALLS:
        r = 1 + _RECORD * k
        words[r] = args[point_query.ARGS_QUERY]
        words[r + 1] = args[point_query.ARGS_USER]
        words[r + 2] = args[point_query.ARGS_IDS] & 0xFFFFFFFF
        words[r + 3] = args[point_query.ARGS_IDS] >> 32
        words[r + 4] = args[point_query.ARGS_CONTEXT]
        log[r + 5] = carray(floats(address + 8 * point_query.ARGS_SIMILARITY), 1)[0]
        query = carray(floats(args[point_query.ARGS_QUERY]), point_query.QUERY_WORDS)
        for j in range(5):
            log[r + 6 + j] = query[j]
    log[0] = k + 1
    return 0


@njit
def _query(scene, scratch, x, y, z, radius, callback, log, stack):
    b = point_query.init_scratch(scratch)
    if stack:  # an instance on the context's stack: world2inst = 2 I (column-major)
        c = b + point_query.QUERY_WORDS
        matrix = scratch.view(np.float32)
        for k in range(16):
            matrix[c + point_query.CONTEXT_WORLD_TO_INSTANCE + k] = 0.0
        for k in (0, 5, 10):
            matrix[c + point_query.CONTEXT_WORLD_TO_INSTANCE + k] = 2.0
        matrix[c + point_query.CONTEXT_WORLD_TO_INSTANCE + 15] = 1.0
        scratch[c + point_query.CONTEXT_STACK_SIZE] = 1
    log[0] = 0.0
    point_query.point_query(scene, scratch, b, x, y, z, radius, callback, log.ctypes.data)
    return b


def _scene():
    # 64 unit triangles in a row along x, 2 apart: a BVH of several levels, whose nodes a
    # query's sphere can miss
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    vertices = np.vstack([corners + np.float32([2 * k, 0, 0]) for k in range(64)])
    bvh = BVH(lanes=1)
    bvh.add_triangles(vertices, np.arange(3 * 64).reshape(-1, 3))
    bvh.commit()
    point_query.register_symbols()
    return bvh


def _run(bvh, point, radius, stack=False):
    scratch = np.zeros(point_query.SCRATCH_WORDS, np.uint32)
    log = np.zeros(1 + _RECORD * _CALLS, np.float64)
    b = _query(
        bvh.committed_scene(),
        scratch,
        *np.float32(point),
        np.float32(radius),
        _record.address,
        log,
        stack,
    )
    calls = int(log[0])
    records = log[1 : 1 + _RECORD * min(calls, _CALLS)].reshape(-1, _RECORD)
    return calls, records, records.view(np.uint64), scratch.ctypes.data + 4 * b, log


def test_callback_arguments_are_what_was_passed():
    bvh = _scene()
    calls, records, words, query_address, log = _run(bvh, [0.2, 0.3, 0.5], np.inf)
    assert 1 <= calls <= _CALLS
    assert 0 in words[:, 2] and words[:, 2].max() < 64  # primID
    assert (words[:, 0] == query_address).all()
    assert (words[:, 1] == log.ctypes.data).all()
    assert (words[:, 3] == 0).all()  # geomID
    assert (words[:, 4] == query_address + 4 * point_query.QUERY_WORDS).all()  # the context
    np.testing.assert_array_equal(records[:, 5], 1.0)  # no instance: similarity scale 1
    expected = np.float32([0.2, 0.3, 0.5, 0.0, np.inf])  # x, y, z, time, radius
    np.testing.assert_array_equal(records[:, 6:11], [expected] * calls)
    assert query_address % 16 == 0


def test_the_radius_word_bounds_the_query():
    bvh = _scene()
    # 0.3 above triangle 0: a radius of 0.5 reaches it and not the far end of the row, 0.29
    # nothing; a radius read from the time word (0) would reach nothing, one read from
    # elsewhere not these
    near = [0.25, 0.25, 0.3]
    assert _run(bvh, near, 0.29)[0] == 0
    calls, _, words, *_ = _run(bvh, near, 0.31)
    assert 1 <= calls < 64 and 0 in words[:, 2] and words[:, 2].max() < 32
    assert _run(bvh, near, np.inf)[0] >= 64  # every triangle (some leaves may repeat one)


def test_the_context_stack_is_read():
    bvh = _scene()
    calls, records, *_ = _run(bvh, [0.1, 0.1, 0.0], np.inf, stack=True)
    assert calls >= 1
    # world2inst = 2 I on a stack of one: Embree's similarity scale is 2
    np.testing.assert_array_equal(records[:, 5], 2.0)
