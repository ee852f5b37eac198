"""The names a user chooses from that the renderer defines: AOVs, tone maps, display curves and
the ways spheres enter the BVH. A module without NumPy, so that ``embree-rt --help`` lists them
without loading the renderer."""

from __future__ import annotations

AOV_NAMES = (
    "depth",
    "z_depth",
    "position",
    "uv",
    "normal",
    "albedo",
    "object_id",
    "material_id",
    "ao",
)
TONEMAPS = ("reinhard", "aces", "none")
TRANSFERS = ("gamma2.2", "srgb")
SPHERE_MODES = ("analytic", "point", "mesh")
# What a camera ray that meets nothing shows: the scene's sky, or (papers' backgrounds) white,
# black, or nothing (an alpha channel).
BACKGROUNDS = ("sky", "white", "black", "transparent")
# OVITO's standard views (``--view``, ``scene.views``).
STANDARD_VIEWS = ("top", "bottom", "front", "back", "left", "right", "iso")
