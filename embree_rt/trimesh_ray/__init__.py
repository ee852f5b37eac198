"""embree_rt's BVH behind trimesh's ray and proximity APIs, with trimesh's float64 rules:
``mesh.ray = RayMeshIntersector(mesh)``, ``mesh.nearest = ProximityQuery(mesh)``, or
``install()`` for every new mesh (``installed``).

The intersector (``intersector``) and the exact-hit pipeline it runs (``exact_hits``: screen ->
settle -> decide -> finish, in one function), on compiled passes that exist only for those rules
(``hit_passes``: first hits screened for float32 doubt, all hits settled, decided in float64
near edges and finished in trimesh's order, one hit per point where a ray meets the surface,
with float64 distances to the triangles' planes, all reading their grouped inputs by name),
over the mesh and its rays in Embree's local frame in a coherent tracing order
(``local_frame``). The proximity queries (``proximity``) on Embree's point query with a float64
closest-triangle callback; ``installed``: every new mesh given both.
"""

from embree_rt.trimesh_ray.installed import install, uninstall
from embree_rt.trimesh_ray.intersector import RayMeshIntersector
from embree_rt.trimesh_ray.proximity import ProximityQuery

__all__ = ["ProximityQuery", "RayMeshIntersector", "install", "uninstall"]
