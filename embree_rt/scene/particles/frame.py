"""``ParticleFrame``: one frame of a particle file, as plain arrays."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np


class Labels(NamedTuple):
    """Per-particle labels (elements or types) as codes into a table, the way ``np.unique``
    returns them: ``names`` (k,) str, distinct, sorted, each used by some particle; ``codes``
    (n,) unsigned integer, particle i's label is ``names[codes[i]]``. A hundred million
    particles of a few kinds take one byte each, and what depends only on a particle's label
    (its colour, its radius) is computed once per name and gathered."""

    names: np.ndarray
    codes: np.ndarray

    def values(self) -> np.ndarray:
        """(n,) str: each particle's label."""
        return gathered(self.names, self.codes)

    def counts(self) -> np.ndarray:
        """(k,) int64: how many particles bear each name."""
        return code_counts(self.codes, len(self.names))


def code_dtype(count: int) -> np.dtype:
    """The smallest unsigned dtype that holds ``count`` distinct codes."""
    return np.dtype(np.uint8 if count <= 1 << 8 else np.uint16 if count <= 1 << 16 else np.uint32)


def smallest_codes(codes: np.ndarray, count: int) -> np.ndarray:
    """``codes`` (n,) in the smallest unsigned dtype that holds ``count`` distinct codes."""
    return codes.astype(code_dtype(count), copy=False)


def coded(values) -> Labels:
    """The ``Labels`` of (n,) labels ``values`` (converted to str)."""
    names, codes = np.unique(np.asarray(values, dtype=str), return_inverse=True)
    return Labels(names, smallest_codes(codes.reshape(-1), len(names)))


# Rows gathered or counted at a time: NumPy turns an index array into a full (n,) intp copy,
# 8 bytes a particle, which a hundred million particles should not pay for a one-byte code.
GATHER_ROWS = 1 << 18


def gathered(table: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """(n, ...) ``table[codes]`` of a (k, ...) ``table`` and (n,) integer ``codes`` in 0..k-1,
    taken in slices of ``GATHER_ROWS``."""
    table = np.asarray(table)
    out = np.empty((len(codes), *table.shape[1:]), table.dtype)
    for start in range(0, len(codes), GATHER_ROWS):
        stop = start + GATHER_ROWS
        np.take(table, codes[start:stop], axis=0, out=out[start:stop])
    return out


def code_counts(codes: np.ndarray, count: int) -> np.ndarray:
    """(count,) int64: how many of the (n,) integer ``codes`` (in 0..count-1) are each code,
    counted in slices of ``GATHER_ROWS``."""
    counts = np.zeros(count, np.int64)
    for start in range(0, len(codes), GATHER_ROWS):
        counts += np.bincount(codes[start : start + GATHER_ROWS], minlength=count)
    return counts


def coded_table(names, codes: np.ndarray) -> Labels:
    """The ``Labels`` of a file's own table: (m,) ``names`` (perhaps unsorted, repeated or
    unused) and (n,) integer ``codes`` in 0..m-1 (a GSD frame's ``types`` and ``typeid``): the
    same as ``coded(names[codes])`` without making the (n,) strings."""
    names = np.asarray(names, dtype=str)
    codes = np.asarray(codes).reshape(-1)
    used = code_counts(codes, len(names)) > 0
    distinct, renumber = np.unique(names[used], return_inverse=True)
    lookup = np.zeros(len(names), np.int64)
    lookup[used] = renumber.reshape(-1)
    return Labels(distinct, gathered(smallest_codes(lookup, len(distinct)), codes))


class LabelValues:
    """An attribute read and set as (n,) str labels (or None) and held as the ``Labels`` in
    the field named ``field`` of the same object: ``ParticleFrame.elements`` and ``types``."""

    def __init__(self, field: str, doc: str) -> None:
        self.field = field
        self.__doc__ = doc

    def __get__(self, owner: object, kind: type | None = None):
        if owner is None:
            return self
        labels = getattr(owner, self.field)
        return None if labels is None else labels.values()

    def __set__(self, owner: object, values) -> None:
        setattr(owner, self.field, None if values is None else coded(values))


@dataclass
class ParticleFrame:
    """The particles of one frame.

    ``positions`` (n, 3) float32 or float64, the reader library's values in its units;
    ``element_labels`` the chemical symbols (``Labels``) or None when the file names none;
    ``type_labels`` the particle types (``Labels``) or None (``elements`` and ``types`` read and
    set them as (n,) str);
    ``radii`` (n,) float64 from the file's radius or diameter column (PQR's radius), or None;
    ``properties`` other per-particle columns, name -> (n,) float64; ``box`` (3, 3) float64
    cell vectors as rows, or None; ``origin`` (3,) float64 the box's lowest corner;
    ``frame`` this frame's number and ``frame_count`` how many the file holds; ``bonds``
    (m, 2) int64 the particles the file says are bonded, or None when it lists none.
    """

    path: str
    positions: np.ndarray
    element_labels: Labels | None = None
    type_labels: Labels | None = None
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

    elements = LabelValues("element_labels", "(n,) str chemical symbols, or None.")
    types = LabelValues("type_labels", "(n,) str particle types, or None.")

    def labels(self) -> tuple[str, np.ndarray]:
        """What names each particle's kind: ("element", elements) where the file names
        elements, else ("type", types), else ("type", all "1")."""
        kind, labelled = self.label_codes()
        return kind, labelled.values()

    def label_codes(self) -> tuple[str, Labels]:
        """``labels`` as ``Labels``: ("element", ...) where the file names elements, else
        ("type", ...), else ("type", every particle "1")."""
        if self.element_labels is not None:
            return "element", self.element_labels
        if self.type_labels is not None:
            return "type", self.type_labels
        return "type", Labels(np.array(["1"]), np.zeros(len(self), np.uint8))

    def subset(self, keep: np.ndarray) -> ParticleFrame:
        """The frame of the particles ``keep`` (n,) bool or (k,) int picks."""

        def pick(values):
            return None if values is None else values[keep]

        def pick_labels(labelled: Labels | None) -> Labels | None:
            return None if labelled is None else coded(labelled.values()[keep])

        return ParticleFrame(
            path=self.path,
            positions=self.positions[keep],
            element_labels=pick_labels(self.element_labels),
            type_labels=pick_labels(self.type_labels),
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
