"""Reading particle files: embree_rt's reader against the libraries' own on the same file.

Writes a LAMMPS text dump (id type x y z vx) and an XYZ file of N particles, then times, each
in turn (median of --repeats): the LAMMPS dump read by embree_rt (NumPy), by ASE
(``lammps-dump-text``) and by MDAnalysis (``LAMMPSDUMP``); the XYZ file by ASE and by
MDAnalysis. Prints JSON: seconds per reader and the ratios to embree_rt's.

    python benchmarks/particles_read.py --count 1000000
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def write_files(folder: Path, count: int) -> tuple[Path, Path]:
    rng = np.random.default_rng(0)
    positions = rng.uniform(0, 100, (count, 3))
    table = np.column_stack(
        [np.arange(1, count + 1), rng.integers(1, 4, count), positions, rng.normal(size=count)]
    )
    dump = folder / "b.lammpstrj"
    with open(dump, "w") as out:
        out.write(f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{count}\n")
        out.write("ITEM: BOX BOUNDS pp pp pp\n0 100\n0 100\n0 100\nITEM: ATOMS id type x y z vx\n")
        np.savetxt(out, table, fmt=["%d", "%d", "%.6f", "%.6f", "%.6f", "%.6f"])
    xyz = folder / "b.xyz"
    with open(xyz, "w") as out:
        out.write(f"{count}\n\n")
        symbols = np.array(["C", "O", "H"])[rng.integers(0, 3, count)]
        for symbol, (x, y, z) in zip(symbols, positions, strict=True):
            out.write(f"{symbol} {x:.6f} {y:.6f} {z:.6f}\n")
    return dump, xyz


def readers(dump: Path, xyz: Path) -> dict:
    import ase.io
    import MDAnalysis

    from embree_rt.scene.particles import read_particles

    return {
        "dump_embree_rt": lambda: read_particles(dump).positions,
        "dump_ase": lambda: ase.io.read(dump, format="lammps-dump-text").positions,
        "dump_mdanalysis": lambda: (
            MDAnalysis.Universe(
                str(dump), format="LAMMPSDUMP", topology_format="LAMMPSDUMP"
            ).atoms.positions
        ),
        "xyz_embree_rt": lambda: read_particles(xyz).positions,
        "xyz_ase": lambda: ase.io.read(xyz, format="extxyz").positions,
        "xyz_mdanalysis": lambda: MDAnalysis.Universe(str(xyz)).atoms.positions,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--count", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        dump, xyz = write_files(Path(folder), args.count)
        timed = readers(dump, xyz)
        seconds: dict[str, list[float]] = {name: [] for name in timed}
        for _ in range(args.repeats):
            for name, read in timed.items():  # in turns
                started = time.perf_counter()
                read()
                seconds[name].append(time.perf_counter() - started)
    median = {name: statistics.median(values) for name, values in seconds.items()}
    ratios = {
        name: median[name] / median[name.split("_")[0] + "_embree_rt"]
        for name in median
        if not name.endswith("embree_rt")
    }
    print(json.dumps({"count": args.count, "seconds": median, "vs_embree_rt": ratios}))


if __name__ == "__main__":
    main()
