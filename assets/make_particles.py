"""Make the particle files of the README's gallery, each with its format's own writer:

- ``helix.pdb`` (ASE's PDB writer): a protein-like alpha helix of 60 residues, backbone N, CA,
  C, O and side chains of C, N, O and S, drawn by element;
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
    for make in (helix, membrane, packing):
        print(make(folder))


if __name__ == "__main__":
    main()
