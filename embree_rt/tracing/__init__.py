"""The renderer's compiled queries on the Embree layer's BVH: hit records that know the ground
plane and the caller's labels (``records``), camera rays made inside the nearest-hit query
(``camera_query``), and shadow segments toward a light made inside the occlusion query
(``segments``). They call the BVH through its public query methods and the kernels' packet
helpers; ``geometry.SceneGeometry`` is their one user in the renderer."""

from embree_rt.tracing.records import GROUPS, HitLabels, HitRecords

__all__ = ["GROUPS", "HitLabels", "HitRecords"]
