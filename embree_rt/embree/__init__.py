"""The sealed Embree layer: the only code in embree_rt that knows about ctypes and numba."""

from embree_rt.embree.bvh import BVH, Hits
from embree_rt.embree.heap import retain_freed_memory
from embree_rt.embree.library import EmbreeError
from embree_rt.embree.records import GROUPS, HitLabels, HitRecords
from embree_rt.embree.spatial_order import spheres_in_spatial_order

__all__ = [
    "BVH", "GROUPS", "EmbreeError", "HitLabels", "HitRecords", "Hits", "retain_freed_memory",
    "spheres_in_spatial_order",
]
