"""embree_rt's BVH behind trimesh's ray and proximity APIs, with trimesh's float64 rules:
``mesh.ray = RayMeshIntersector(mesh)``, ``mesh.nearest = ProximityQuery(mesh)``, or
``install()`` for every new mesh (``installed``).

The intersector (``intersector``) and the exact-hit pipeline it runs (``exact_hits``: screen ->
settle -> decide -> finish), on compiled passes that exist only for those rules: the mesh in
Embree's local frame (``local_scene``, ``local_frame``) in a coherent tracing order, first hits
screened for float32 doubt (``screened_nearest``), all hits settled (``settled_hits``), decided
in float64 near edges (``decided_hits``) and finished in trimesh's order, one hit per point
where a ray meets the surface (``finished_hits``), with float64 distances to the triangles'
planes (``plane_distances``), all reading their grouped inputs by name (``hit_inputs``). The
proximity queries (``proximity``) on Embree's point query with a float64 closest-triangle
callback.
"""

from embree_rt.trimesh_ray.installed import install, uninstall
from embree_rt.trimesh_ray.intersector import RayMeshIntersector
from embree_rt.trimesh_ray.proximity import ProximityQuery

__all__ = ["ProximityQuery", "RayMeshIntersector", "install", "uninstall"]
