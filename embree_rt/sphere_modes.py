"""How spheres enter the BVH: the modes a user picks (``SPHERE_MODES``) and the kind of Embree
geometry a count of spheres becomes in each (``sphere_kind``), which the geometry builds and the
memory budget prices."""

from __future__ import annotations

from embree_rt.choices import SPHERE_MODES

__all__ = ["SPHERE_MODES", "USER_GEOMETRY_MAX_SPHERES", "sphere_kind"]

# Above this many spheres, "analytic" spheres are Embree's own point spheres. Measured on the
# 1e7-sphere random field (2 threads, benchmarks/build_quality.py): they trace as fast as user
# geometry there (primary 9.3-9.6 against 10.3-13.7 Mrays/s, shadow 12.3-14.4 against 12.4-12.9),
# build in 2.9 s instead of 5.0-5.4 s, and take 49 bytes a sphere in Embree instead of 93 (the
# whole command: 71 against 148), so 1e8 spheres fit in 8 GB. Below it user geometry traces up to
# 1.5x faster.
USER_GEOMETRY_MAX_SPHERES = 1 << 23


def sphere_kind(count: int, spheres: str = "analytic") -> str:
    """How ``count`` spheres of mode ``spheres`` (``SPHERE_MODES``) enter the BVH: "user" or
    "point" (the ``BVH.add_spheres`` kinds), or "mesh" (instanced icospheres)."""
    if spheres == "mesh":
        return "mesh"
    if spheres == "point" or count > USER_GEOMETRY_MAX_SPHERES:
        return "point"
    return "user"
