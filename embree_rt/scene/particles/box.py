"""The simulation box drawn as thin lines: its 12 edges as segments of round linear curves."""

from __future__ import annotations

import itertools

import numpy as np

# The edges' radius as a share of the box's longest body diagonal: thin beside the particles
# (a 10-diameter box of unit particles gets edges of radius ~0.05) yet a few pixels wide at
# the framed view's resolution.
BOX_RADIUS_SHARE = 0.003
# The edges' colour (linear RGB): a dark grey that reads on the sky and on the floor.
BOX_COLOR = (0.08, 0.08, 0.08)


def box_edges(box: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(24, 3) float64 end points of the 12 edges of the parallelepiped with cell vectors
    ``box`` (3, 3) float64 as rows and lowest corner ``origin`` (3,): edge e runs from point
    2e to point 2e + 1 (four edges along each cell vector)."""
    box = np.asarray(box, np.float64)
    origin = np.asarray(origin, np.float64)
    points = []
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        for i, j in itertools.product((0, 1), repeat=2):
            start = origin + i * box[others[0]] + j * box[others[1]]
            points += [start, start + box[axis]]
    return np.array(points)


def box_radius(box: np.ndarray) -> float:
    """The edges' radius for cell vectors ``box`` (3, 3): ``BOX_RADIUS_SHARE`` of the longest
    of its four body diagonals."""
    box = np.asarray(box, np.float64)
    signs = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], np.float64)
    return BOX_RADIUS_SHARE * float(np.linalg.norm(signs @ box, axis=1).max())
