"""PLY triangle strips, which trimesh reads as a point cloud: ``element tristrips`` with a
``vertex_indices`` list per strip (-1 restarts a strip; triangle k of a run is (s[k], s[k+1],
s[k+2]) for even k and (s[k+1], s[k], s[k+2]) for odd k, so that all face the same way), as
scanned models (the Stanford scans among them) are stored. A PLY whose elements give no
triangle says which elements it holds and which of them embree_rt cannot read."""

from __future__ import annotations

import numpy as np
import trimesh

from embree_rt.scene.errors import MeshFileError

# The PLY elements embree_rt reads triangles from; "vertex" holds the points they index.
TRIANGLE_ELEMENTS = ("face", "tristrips")


def strip_triangles(strips: list[np.ndarray]) -> np.ndarray:
    """(t, 3) int64 triangles of triangle strips, each a 1-D array of vertex indices in which
    -1 restarts the strip; degenerate triangles (a repeated index, which strips use to turn or
    to join runs) are left out."""
    flat = np.concatenate(
        [np.append(np.asarray(s, np.int64).ravel(), -1) for s in strips] or [np.zeros(0, np.int64)]
    )
    k = np.arange(len(flat) - 2)
    valid = (flat[:-2] >= 0) & (flat[1:-1] >= 0) & (flat[2:] >= 0)
    # the position of each index in its run: distance from the last restart before it
    run_start = np.maximum.accumulate(np.where(flat < 0, np.arange(len(flat)) + 1, 0))
    odd = ((k - run_start[:-2]) % 2 == 1)[valid]
    k = k[valid]
    triangles = np.stack([flat[k], flat[k + 1], flat[k + 2]], axis=1)
    triangles[odd, 0], triangles[odd, 1] = flat[k[odd] + 1], flat[k[odd]]
    degenerate = (
        (triangles[:, 0] == triangles[:, 1])
        | (triangles[:, 1] == triangles[:, 2])
        | (triangles[:, 0] == triangles[:, 2])
    )
    return triangles[~degenerate]


def with_strips(loaded: object) -> object:
    """What trimesh loaded from a PLY, with the triangles of its ``tristrips`` element added
    (a Trimesh, carrying the points' vertex colours); as loaded when it has none. Raises
    ``MeshFileError`` naming the elements when the file holds no triangle embree_rt reads."""
    metadata = getattr(loaded, "metadata", None) or {}
    elements = metadata.get("_ply_raw") or {}  # trimesh keeps the parsed PLY elements here
    strips = elements.get("tristrips")
    if strips is not None:
        # ASCII: a dict of arrays (an object array when the lists differ in length); binary:
        # a structured array with a field of one fixed length
        data = strips.get("data") if isinstance(strips, dict) else None
        names = data.dtype.names if isinstance(data, np.ndarray) else data
        lists = data["vertex_indices"] if names and "vertex_indices" in names else None
        if lists is None:
            raise MeshFileError("element 'tristrips'", "has no 'vertex_indices' list to read")
        if isinstance(lists, np.ndarray) and lists.dtype.names:  # binary: (length, list) pairs
            lists = lists[lists.dtype.names[-1]]
        faces = strip_triangles(list(lists))
        if isinstance(loaded, trimesh.Trimesh):
            faces = np.concatenate([np.asarray(loaded.faces, np.int64), faces])
            colors = loaded.visual.vertex_colors if loaded.visual.kind == "vertex" else None
        else:
            colors = getattr(loaded, "colors", None)
            colors = colors if colors is not None and len(colors) else None
        return trimesh.Trimesh(
            np.asarray(loaded.vertices),
            faces,
            vertex_colors=colors,
            process=False,
            metadata=metadata,
        )
    if isinstance(loaded, trimesh.Trimesh) and len(loaded.faces):
        return loaded
    others = [name for name in elements if name != "vertex"]
    unread = [name for name in others if name not in TRIANGLE_ELEMENTS]
    if unread:
        raise MeshFileError(
            f"element {unread[0]!r}",
            f"not an element embree_rt reads triangles from (it reads "
            f"{', '.join(TRIANGLE_ELEMENTS)}; the file has {', '.join(elements)})",
        )
    if not others:
        raise MeshFileError("(file)", "only vertices (a point cloud): no face or tristrips element")
    return loaded
