"""Compiled helpers that know nothing of Embree: raw pointers and prefetch, how many threads a
batch is worth (and the lock every parallel region takes), Morton codes and their radix sort,
and the C heap's tuning for the renderer's short-lived arrays."""

from embree_rt.compiled.heap import retain_freed_memory

__all__ = ["retain_freed_memory"]
