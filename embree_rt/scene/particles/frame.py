"""``ParticleFrame``: one frame of a particle file, as plain arrays."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ParticleFrame:
    """The particles of one frame.

    ``positions`` (n, 3) float64 in the reader library's units; ``elements`` (n,) str chemical
    symbols or None when the file names none; ``types`` (n,) str particle types or None;
    ``radii`` (n,) float64 from the file's radius or diameter column (PQR's radius), or None;
    ``properties`` other per-particle columns, name -> (n,) float64; ``box`` (3, 3) float64
    cell vectors as rows, or None; ``origin`` (3,) float64 the box's lowest corner;
    ``frame`` this frame's number and ``frame_count`` how many the file holds; ``bonds``
    (m, 2) int64 the particles the file says are bonded, or None when it lists none.
    """

    path: str
    positions: np.ndarray
    elements: np.ndarray | None = None
    types: np.ndarray | None = None
    radii: np.ndarray | None = None
    properties: dict[str, np.ndarray] = field(default_factory=dict)
    box: np.ndarray | None = None
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    frame: int = 0
    frame_count: int = 1
    bonds: np.ndarray | None = None
    # The reader library's own object (an MDAnalysis Universe), for its selection language.
    source: object | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.positions)

    def labels(self) -> tuple[str, np.ndarray]:
        """What names each particle's kind: ("element", elements) where the file names
        elements, else ("type", types), else ("type", all "1")."""
        if self.elements is not None:
            return "element", self.elements
        if self.types is not None:
            return "type", self.types
        return "type", np.full(len(self), "1")

    def subset(self, keep: np.ndarray) -> ParticleFrame:
        """The frame of the particles ``keep`` (n,) bool or (k,) int picks."""

        def pick(values):
            return None if values is None else values[keep]

        return ParticleFrame(
            path=self.path,
            positions=self.positions[keep],
            elements=pick(self.elements),
            types=pick(self.types),
            radii=pick(self.radii),
            properties={name: values[keep] for name, values in self.properties.items()},
            box=self.box,
            origin=self.origin,
            frame=self.frame,
            frame_count=self.frame_count,
            bonds=None if self.bonds is None else kept_bonds(self.bonds, keep, len(self)),
        )


def kept_bonds(bonds: np.ndarray, keep: np.ndarray, count: int) -> np.ndarray:
    """(m', 2) int64: the ``bonds`` (m, 2) among ``count`` particles whose two particles
    ``keep`` (count,) bool or (k,) int picks, renumbered as the kept particles are."""
    number = np.full(count, -1, np.int64)
    kept = np.arange(count)[keep]
    number[kept] = np.arange(len(kept))
    renumbered = number[np.asarray(bonds, np.int64)].reshape(-1, 2)
    return renumbered[(renumbered >= 0).all(axis=1)]
