"""Data-parallel rendering: the scene cut into K spatial bricks, each with its own BVH.

``partition`` splits space (a k-d tree on object centres), ``contents`` cuts a brick's objects
out of a scene or generates them from a random field's recipe, ``brick`` answers one brick's
queries, ``ray_boxes`` routes rays to the bricks they can reach, ``nearest`` keeps the nearest
hit over bricks (the tie rule), ``brick_set`` puts it together as the integrator's tracer, and
``cluster`` holds the bricks on Dask workers (``pip install 'embree-rt[distributed]'``).
"""

from embree_rt.bricks.brick_set import BrickSet, local_brick_set
from embree_rt.bricks.partition import Partition, field_partition, scene_partition

__all__ = ["BrickSet", "Partition", "field_partition", "local_brick_set", "scene_partition"]
