"""The sealed Embree layer: the only code in embree_rt that knows about ctypes and numba."""

from embree_rt.embree.bvh import BVH, Hits
from embree_rt.embree.heap import retain_freed_memory
from embree_rt.embree.library import EmbreeError

__all__ = ["BVH", "EmbreeError", "Hits", "retain_freed_memory"]
