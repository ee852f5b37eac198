r"""Reading particle files: embree_rt's reader against the libraries' own on the same file.

Writes a LAMMPS text dump (id type x y z vx) and an XYZ file of N particles, then times, each
in turn (median of --repeats): the LAMMPS dump read by embree_rt (NumPy), by ASE
(``lammps-dump-text``) and by MDAnalysis (``LAMMPSDUMP``); the XYZ file by ASE and by
MDAnalysis. Prints JSON: seconds per reader and the ratios to embree_rt's.

With ``--dump FILE`` (a one-frame dump of numeric columns, such as OVITO's exporter writes)
it compares instead the ways to parse the dump's rows into float64 columns, each in a fresh
process, in turns: embree_rt's parser (numba, ``text_columns``), ``np.loadtxt``,
``np.fromstring``, ``pandas.read_csv(sep=r"\s+")``, ``pyarrow.csv`` and ``polars`` (the last
three where installed; pyarrow and polars take one separator byte, so only a dump with single
spaces). JSON: each one's numbers a second, peak memory (MB, the process's), and whether its
values equal ``np.loadtxt``'s bit for bit; embree_rt's ``first_call_s`` is numba's one-off
start in a process (its cache loaded), timed apart: a render pays it for its other kernels.

    python benchmarks/particles_read.py --count 1000000
    python benchmarks/particles_read.py --dump x.dump --repeats 3
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
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


# One parse of the dump in argv[2] by the parser argv[1]; prints seconds, numbers, peak MB, and
# the sha256 of the float64 columns (row-major) to compare bit for bit.
PARSE_SCRIPT = """
import hashlib, resource, sys, time
import numpy as np

name, path = sys.argv[1], sys.argv[2]
with open(path, "rb") as handle:
    head = [handle.readline() for _ in range(9)]
count = int(head[3])
columns = [c.decode() for c in head[8].split()[2:]]
width = len(columns)
trailing_space = head[-1] and open(path, "rb").read(1 << 16).split(b"\\n")[9].endswith(b" ")
names = columns + ["_"] * bool(trailing_space)
# The libraries are imported before the clock starts; numba's cache is loaded after.
if name == "embree_rt":
    from embree_rt.scene.particles.lammps_dump import map_file
    from embree_rt.scene.particles.text_columns import parse_columns
elif name in ("pandas", "polars", "pyarrow"):
    import importlib

    library = importlib.import_module(name + (".csv" if name == "pyarrow" else ""))
first_call = 0.0
if name == "embree_rt":  # numba's one-off start (its cache loaded), paid once a process
    first_call = time.perf_counter()
    parse_columns(np.frombuffer(b"1", np.uint8), 1, np.zeros(1, bool), (0,))
    first_call = time.perf_counter() - first_call
started = time.perf_counter()
if name == "embree_rt":
    data = map_file(path)
    body = data.find(b"\\n", data.find(b"ITEM: ATOMS")) + 1
    table = parse_columns(
        np.frombuffer(data, np.uint8, offset=body), count, np.zeros(width, bool),
        tuple(range(width)),
    ).block
elif name == "loadtxt":
    table = np.loadtxt(path, skiprows=9, ndmin=2)
elif name == "fromstring":
    table = np.fromstring(open(path, "rb").read().split(b"\\n", 9)[9], sep=" ")
    table = table.reshape(count, width)
elif name == "pandas":
    frame = library.read_csv(
        path, sep=r"\\s+", skiprows=9, header=None, names=columns, dtype=np.float64
    )
    table = frame.to_numpy()
elif name == "pyarrow":
    frame = library.read_csv(
        path,
        read_options=library.ReadOptions(skip_rows=9, column_names=names),
        parse_options=library.ParseOptions(delimiter=" "),
        convert_options=library.ConvertOptions(
            column_types={c: "float64" for c in columns}, include_columns=columns
        ),
    )
    table = np.stack([frame.column(c).to_numpy() for c in columns], axis=1)
elif name == "polars":
    frame = library.read_csv(
        path, separator=" ", skip_rows=9, has_header=False, new_columns=names,
        schema_overrides={c: library.Float64 for c in columns},
    )
    table = frame.select(columns).to_numpy()
seconds = time.perf_counter() - started
digest = hashlib.sha256(np.ascontiguousarray(table, np.float64).tobytes()).hexdigest()
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(seconds, table.size, peak, digest, first_call)
"""
PARSERS = ("embree_rt", "loadtxt", "fromstring", "pandas", "pyarrow", "polars")


def installed(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def compare_parsers(dump: Path, repeats: int, names: list[str]) -> dict:
    """Each parser's median numbers a second and peak MB on ``dump``, fresh processes in
    turns (a warm-up round first: the file in the disk cache, numba's cache made)."""
    names = [n for n in names if n in ("embree_rt", "loadtxt", "fromstring") or installed(n)]
    runs: dict[str, list[list[str]]] = {name: [] for name in names}
    for turn in range(repeats + 1):
        for name in names:
            done = subprocess.run(
                [sys.executable, "-c", PARSE_SCRIPT, name, str(dump)],
                capture_output=True,
                text=True,
                check=True,
            )
            if turn:
                runs[name].append(done.stdout.split())
    reference = runs["loadtxt"][0][3] if "loadtxt" in runs else None
    out = {}
    for name, lines in runs.items():
        seconds = statistics.median(float(line[0]) for line in lines)
        out[name] = {
            "numbers_per_s": round(int(lines[0][1]) / seconds),
            "seconds": round(seconds, 3),
            "peak_mb": round(statistics.median(float(line[2]) for line in lines)),
            "equals_loadtxt": lines[0][3] == reference if reference else None,
            "first_call_s": round(statistics.median(float(line[4]) for line in lines), 3),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--count", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--dump", type=Path, help="compare the row parsers on this dump")
    parser.add_argument("--parsers", nargs="*", choices=PARSERS, default=list(PARSERS))
    args = parser.parse_args()
    if args.dump is not None:
        print(
            json.dumps(
                {
                    "dump": str(args.dump),
                    "parsers": compare_parsers(args.dump, args.repeats, args.parsers),
                }
            )
        )
        return
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
