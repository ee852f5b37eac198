"""The (n, 4) float32 (x, y, z, radius) buffer both kinds of sphere are stored in, filled in one
compiled pass that also measures how far from the origin the spheres reach.

NumPy took 16 ns a sphere to fill it (two strided copies) and 78 ns to measure it: ``np.abs``
makes an (n, 3) temporary and ``max(axis=1)`` on a 3-wide axis runs NumPy's slow reduction
loop; 1e8 spheres spent 9 s there. The compiled pass takes 6 ns.
"""

from __future__ import annotations

import numpy as np
from numba import njit

IN_GIVEN_ORDER = np.zeros(0, np.int32)


@njit(nogil=True, cache=True)
def pack_spheres(centers, radii, order, out):
    """Write sphere ``order[k]`` (sphere k when ``order`` is empty) of ``centers`` (n, 3) and
    ``radii`` (n,) float32 into row k of ``out`` (n, 4) float32 as (x, y, z, r). Returns the
    spheres' reach: the largest ``max(|x|, |y|, |z|) + r``, as float32 arithmetic gives it
    (0 for no spheres)."""
    reach = np.float32(0.0)
    reordered = len(order) > 0
    for k in range(out.shape[0]):
        i = order[k] if reordered else k
        x = centers[i, 0]
        y = centers[i, 1]
        z = centers[i, 2]
        r = radii[i]
        out[k, 0] = x
        out[k, 1] = y
        out[k, 2] = z
        out[k, 3] = r
        reach = max(reach, max(abs(x), abs(y), abs(z)) + r)
    return reach
