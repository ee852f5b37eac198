"""The files an OBJ names, checked before trimesh reads it: trimesh says nothing when a material
library or a texture is missing, and the mesh renders plain. Each missing file is one warning
line naming the file that names it, the key (``mtllib``, ``map_Kd``) and the name as written.
Names are looked for as ``mesh_companions.candidate_paths`` says (Windows separators too)."""

from __future__ import annotations

from pathlib import Path

from embree_rt.scene.errors import warn_input
from embree_rt.scene.mesh_companions import candidate_paths, first_line_after


def _found(root: Path, name: str) -> Path | None:
    return next((path for path in candidate_paths(root, name) if path.is_file()), None)


def check_obj_files(path: Path) -> None:
    """Warn (``InputWarning``) for the material library of the OBJ at ``path`` and each
    texture (``map_Kd``) of that library that cannot be found."""
    name = first_line_after(path, b"mtllib")
    if not name:
        return
    library = _found(path.parent, name)
    if library is None:
        warn_input(
            f"{path}: mtllib: no such file {name!r} (looked in {path.parent}); its "
            "materials render as the default"
        )
        return
    material = None
    for line in library.read_text(encoding="utf-8", errors="replace").splitlines():
        words = line.strip().split()
        if len(words) > 1 and words[0].lower() == "newmtl":
            material = " ".join(words[1:])
        elif len(words) > 1 and words[0].lower() == "map_kd":
            texture = line[line.lower().index("map_kd") + len("map_kd") :].strip()
            if _found(path.parent, texture) is None:
                warn_input(
                    f"{library}: map_Kd (material {material!r}): no such file "
                    f"{texture!r} (looked in {path.parent}); the material renders "
                    "without its texture"
                )
