"""The Embree layer: the only code in embree_rt that speaks Embree's ABI (ctypes, and numba
kernels that call Embree or read its structs)."""

from embree_rt.embree.bvh import BVH, GeometryFilter, Hits
from embree_rt.embree.kernels import Rays
from embree_rt.embree.library import EmbreeError
from embree_rt.embree.spatial_order import spheres_in_spatial_order

__all__ = ["BVH", "EmbreeError", "GeometryFilter", "Hits", "Rays", "spheres_in_spatial_order"]
