"""embree_rt's BVH behind trimesh's ray API, with trimesh's float64 rules: ``mesh.ray =
RayMeshIntersector(mesh)``, or ``install()`` for every new mesh (see ``intersector``).

The intersector and the compiled passes that exist only for those rules: the mesh in Embree's
local frame (``local_scene``, ``local_frame``), a coherent tracing order (``ray_order``), first
hits screened for float32 doubt (``screened_nearest``), all hits settled (``settled_hits``),
decided in float64 near edges (``decided_hits``) and finished in trimesh's order
(``finished_hits``), with float64 distances to the triangles' planes (``plane_distances``).
"""

from embree_rt.trimesh_ray.intersector import RayMeshIntersector, install, uninstall

__all__ = ["RayMeshIntersector", "install", "uninstall"]
