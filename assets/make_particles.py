"""Make the particle files of the README's gallery, each with its format's own writer:

- ``helix.pdb`` (ASE's PDB writer): a protein-like alpha helix of 60 residues, backbone N, CA,
  C, O and side chains of C, N, O and S, drawn by element;
- ``peptide.pdb`` (MDAnalysis's PDB writer, its bonds as CONECT records): an alpha-helical
  peptide of 14 residues (Ala, Val, Ser) with its hydrogens, every atom placed from ideal
  bond lengths, angles and the helix's torsions, drawn in ball-and-stick;
- ``membrane.gsd`` (gsd.hoomd): a coarse-grained lipid bilayer, one head and two tail beads a
  lipid, drawn by type;
- ``packing.lammpstrj`` (written by hand, as LAMMPS writes ``dump custom``; no library writes
  one): a polydisperse granular packing with a ``radius`` column and a velocity ``vz``, drawn
  by that property.

Deterministic (seeded): ``python assets/make_particles.py [FOLDER]`` (default: ``assets/``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def helix(folder: Path) -> Path:
    import ase
    import ase.io

    rng = np.random.default_rng(35)
    symbols, positions = [], []
    rise, turn, radius = 1.5, np.radians(100.0), 2.3
    backbone = (("N", -0.35, 0.0), ("C", 0.0, 0.0), ("C", 0.45, 0.3), ("O", 0.6, 1.5))
    for residue in range(60):
        angle = residue * turn
        for symbol, phase, lift in backbone:
            a = angle + phase
            positions.append((radius * np.cos(a), radius * np.sin(a), residue * rise + lift))
            symbols.append(symbol)
        outward = np.array([np.cos(angle), np.sin(angle), 0.0])
        base = np.array([radius * np.cos(angle), radius * np.sin(angle), residue * rise])
        chain = rng.integers(1, 5)
        for k in range(chain):
            step = outward * 1.5 * (k + 1) + rng.normal(0, 0.4, 3)
            kind = (
                "C" if k < chain - 1 else rng.choice(["C", "N", "O", "S"], p=[0.4, 0.3, 0.2, 0.1])
            )
            positions.append(tuple(base + step))
            symbols.append(str(kind))
    path = folder / "helix.pdb"
    ase.io.write(path, ase.Atoms(symbols=symbols, positions=positions))
    return path


# Ideal geometry (Engh & Huber): bond lengths in angstrom, angles and torsions in degrees.
BACKBONE = {"N-CA": 1.458, "CA-C": 1.525, "C-N": 1.329, "C-O": 1.231}
ANGLES = {"N-CA-C": 111.2, "CA-C-N": 116.2, "C-N-CA": 121.7, "CA-C-O": 120.5}
HELIX = {"phi": -57.0, "psi": -47.0, "omega": 180.0}
C_H, N_H, O_H, C_C, C_O = 1.09, 1.01, 0.96, 1.53, 1.417
TETRAHEDRAL = 109.5
# Side chains: (name, bonded to, reference atoms for the torsion, bond, angle, torsion), each
# placed from the three atoms named (a, b, c: the new atom bonds to c).
SIDE_CHAINS = {
    "ALA": [
        ("HB1", ("N", "CA", "CB"), C_H, TETRAHEDRAL, 60.0),
        ("HB2", ("N", "CA", "CB"), C_H, TETRAHEDRAL, 180.0),
        ("HB3", ("N", "CA", "CB"), C_H, TETRAHEDRAL, -60.0),
    ],
    "VAL": [
        ("CG1", ("N", "CA", "CB"), C_C, 110.5, 180.0),
        ("CG2", ("N", "CA", "CB"), C_C, 110.5, -60.0),
        ("HB", ("N", "CA", "CB"), C_H, TETRAHEDRAL, 60.0),
        *(
            (f"HG{g}{h}", ("CA", "CB", f"CG{g}"), C_H, TETRAHEDRAL, torsion)
            for g in (1, 2)
            for h, torsion in ((1, 60.0), (2, 180.0), (3, -60.0))
        ),
    ],
    "SER": [
        ("OG", ("N", "CA", "CB"), C_O, 111.0, 60.0),
        ("HB2", ("N", "CA", "CB"), C_H, TETRAHEDRAL, 180.0),
        ("HB3", ("N", "CA", "CB"), C_H, TETRAHEDRAL, -60.0),
        ("HG", ("CA", "CB", "OG"), O_H, TETRAHEDRAL, 180.0),
    ],
}
SEQUENCE = ["ALA", "VAL", "SER", "ALA", "VAL", "ALA", "SER"] * 2


def placed(a: np.ndarray, b: np.ndarray, c: np.ndarray, bond: float, angle: float, torsion: float):
    """The point d with |cd| = ``bond``, angle bcd = ``angle`` and torsion abcd = ``torsion``
    (degrees): the natural extension reference frame (Parsons et al. 2005)."""
    bc = (c - b) / np.linalg.norm(c - b)
    normal = np.cross(b - a, bc)
    normal /= np.linalg.norm(normal)
    angle, torsion = np.radians(angle), np.radians(torsion)
    local = bond * np.array(
        [-np.cos(angle), np.sin(angle) * np.cos(torsion), np.sin(angle) * np.sin(torsion)]
    )
    return c + local[0] * bc + local[1] * np.cross(normal, bc) + local[2] * normal


def along_x(positions: np.ndarray, axis_atoms: list[int]) -> np.ndarray:
    """(n, 3) ``positions`` turned so the helix's axis (from the mean of its first four
    ``axis_atoms`` to that of its last four) runs along +x, moved to lie 3 angstrom inside the
    box from the origin (PDB's box starts there): Rodrigues' rotation, no decomposition whose
    signs a library may choose."""
    axis = positions[axis_atoms[-4:]].mean(axis=0) - positions[axis_atoms[:4]].mean(axis=0)
    axis /= np.linalg.norm(axis)
    target = np.array([1.0, 0.0, 0.0])
    v, cosine = np.cross(axis, target), float(axis @ target)
    skew = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    rotation = np.eye(3) + skew + skew @ skew / (1.0 + cosine)
    turned = positions @ rotation.T
    return turned - turned.min(axis=0) + 3.0


def peptide(folder: Path) -> Path:
    import warnings

    import MDAnalysis

    names, residues, positions, bonds = [], [], [], []
    index: dict[tuple[int, str], int] = {}

    def add(residue: int, name: str, point: np.ndarray, bonded: tuple[int, str] | None) -> None:
        index[residue, name] = len(names)
        names.append(name)
        residues.append(residue)
        positions.append(point)
        if bonded is not None:
            bonds.append((index[bonded], index[residue, name]))

    def at(residue: int, name: str) -> np.ndarray:
        return positions[index[residue, name]]

    # The first residue's N, CA and C in a plane; every later atom from three placed ones.
    add(0, "N", np.zeros(3), None)
    add(0, "CA", np.array([BACKBONE["N-CA"], 0.0, 0.0]), (0, "N"))
    theta = np.radians(180.0 - ANGLES["N-CA-C"])
    start = at(0, "CA") + BACKBONE["CA-C"] * np.array([np.cos(theta), np.sin(theta), 0.0])
    add(0, "C", start, (0, "CA"))
    last = len(SEQUENCE) - 1
    for i, kind in enumerate(SEQUENCE):
        n, ca, c = at(i, "N"), at(i, "CA"), at(i, "C")
        if i < last:
            add(
                i + 1,
                "N",
                placed(n, ca, c, BACKBONE["C-N"], ANGLES["CA-C-N"], HELIX["psi"]),
                (i, "C"),
            )
            n1 = at(i + 1, "N")
            add(
                i + 1,
                "CA",
                placed(ca, c, n1, BACKBONE["N-CA"], ANGLES["C-N-CA"], HELIX["omega"]),
                (i + 1, "N"),
            )
            ca1 = at(i + 1, "CA")
            add(
                i + 1,
                "C",
                placed(c, n1, ca1, BACKBONE["CA-C"], ANGLES["N-CA-C"], HELIX["phi"]),
                (i + 1, "CA"),
            )
        add(
            i,
            "O",
            placed(n, ca, c, BACKBONE["C-O"], ANGLES["CA-C-O"], HELIX["psi"] + 180.0),
            (i, "C"),
        )
        if i == last:  # the C terminus: a carboxylate's second oxygen where N would be
            add(i, "OXT", placed(n, ca, c, 1.25, ANGLES["CA-C-N"], HELIX["psi"]), (i, "C"))
        if i == 0:  # the N terminus: NH3+
            for h, torsion in ((1, 60.0), (2, 180.0), (3, -60.0)):
                add(i, f"H{h}", placed(c, ca, n, N_H, TETRAHEDRAL, torsion), (i, "N"))
        else:  # the amide H, opposite the previous residue's C about N
            add(i, "H", placed(c, ca, n, N_H, 119.0, HELIX["phi"] + 180.0), (i, "N"))
        add(i, "HA", placed(c, n, ca, C_H, TETRAHEDRAL, 118.0), (i, "CA"))
        add(i, "CB", placed(c, n, ca, C_C, 110.5, -122.5), (i, "CA"))
        for name, (a, b, parent), bond, angle, torsion in SIDE_CHAINS[kind]:
            point = placed(at(i, a), at(i, b), at(i, parent), bond, angle, torsion)
            add(i, name, point, (i, parent))
    positions = along_x(np.array(positions), [index[i, "CA"] for i in range(len(SEQUENCE))])
    universe = MDAnalysis.Universe.empty(
        len(names), n_residues=len(SEQUENCE), atom_resindex=residues, trajectory=True
    )
    universe.atoms.positions = positions
    # A box around it with 3 angstrom to spare (a real CRYST1, not a reader's placeholder)
    universe.dimensions = [*(np.ptp(positions, axis=0) + 6.0), 90.0, 90.0, 90.0]
    universe.add_TopologyAttr("names", names)
    universe.add_TopologyAttr("elements", [name[0] for name in names])
    universe.add_TopologyAttr("resnames", SEQUENCE)
    universe.add_TopologyAttr("resids", np.arange(1, len(SEQUENCE) + 1))
    universe.add_TopologyAttr("bonds", bonds)
    path = folder / "peptide.pdb"
    with warnings.catch_warnings():  # (no chain IDs, record types, ... : PDB's defaults)
        warnings.simplefilter("ignore")
        with MDAnalysis.Writer(str(path), bonds="all") as writer:
            writer.write(universe.atoms)
    return path


def membrane(folder: Path) -> Path:
    import gsd.hoomd

    rng = np.random.default_rng(36)
    side, spacing = 24, 1.0
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2)
    positions, types = [], []
    for leaflet in (1.0, -1.0):
        xy = (grid - side / 2) * spacing + rng.normal(0, 0.08, grid.shape)
        wave = 0.8 * np.sin(xy[:, 0] / 4.0) * np.cos(xy[:, 1] / 5.0)
        for depth, kind in ((3.0, 0), (2.0, 1), (1.0, 2)):
            z = wave + leaflet * (depth * 0.9 + 0.1) + rng.normal(0, 0.05, len(xy))
            positions.append(np.column_stack([xy, z]))
            types.append(np.full(len(xy), kind))
    positions = np.concatenate(positions).astype(np.float32)
    frame = gsd.hoomd.Frame()
    frame.particles.N = len(positions)
    frame.particles.position = positions
    frame.particles.types = ["head", "tail1", "tail2"]
    frame.particles.typeid = np.concatenate(types).astype(np.uint32)
    frame.particles.diameter = np.full(len(positions), 1.0, np.float32)
    frame.configuration.box = [side * spacing, side * spacing, 12.0, 0, 0, 0]
    path = folder / "membrane.gsd"
    with gsd.hoomd.open(str(path), "w") as trajectory:
        trajectory.append(frame)
    return path


def packing(folder: Path) -> Path:
    rng = np.random.default_rng(37)
    cells = 14
    grid = np.stack(np.meshgrid(*[np.arange(cells)] * 3, indexing="ij"), -1).reshape(-1, 3)
    positions = (grid + 0.5 + rng.uniform(-0.12, 0.12, grid.shape)) * 1.0
    radii = rng.uniform(0.3, 0.38, len(grid))
    keep = positions[:, 2] < cells * (0.55 + 0.35 * np.cos(positions[:, 0] / cells * np.pi) ** 2)
    positions, radii = positions[keep], radii[keep]
    vz = -0.2 * positions[:, 2] + rng.normal(0, 0.3, len(radii))
    path = folder / "packing.lammpstrj"
    with open(path, "w") as out:
        out.write(f"ITEM: TIMESTEP\n1000\nITEM: NUMBER OF ATOMS\n{len(radii)}\n")
        out.write(f"ITEM: BOX BOUNDS pp pp fm\n0 {cells}\n0 {cells}\n0 {cells}\n")
        out.write("ITEM: ATOMS id type x y z vz radius\n")
        for i, ((x, y, z), v, r) in enumerate(zip(positions, vz, radii, strict=True)):
            out.write(f"{i + 1} 1 {x:.5f} {y:.5f} {z:.5f} {v:.5f} {r:.5f}\n")
    return path


def main() -> None:
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent
    for make in (helix, peptide, membrane, packing):
        print(make(folder))


if __name__ == "__main__":
    main()
