"""Bad particle files on the command line, each: one line naming the file and the problem,
exit code 2, nothing written and an existing output left as it was. (tests/test_particles.py
holds a truncated dump, a NaN coordinate, a zero radius, a 10^12-atom dump header, a frame
past the end and an empty XYZ; these are the rest of issue 35's list, in more formats.)"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ase_io = pytest.importorskip("ase.io")
import ase.build  # noqa: E402
import MDAnalysis  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
KEPT = b"an image already here"
DUMP_HEAD = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n" + (
    "0 10\n" * 3
)


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args], cwd=cwd, env=env, capture_output=True, text=True
    )


def water_trajectory(folder: Path) -> None:
    """w.pdb (3 atoms) and w.dcd (2 frames of them) by MDAnalysis's writers, and big.pdb, a
    topology of another atom count."""
    water = MDAnalysis.Universe.empty(3, trajectory=True, atom_resindex=[0, 0, 0])
    water.add_TopologyAttr("names", ["O", "H1", "H2"])
    water.add_TopologyAttr("resnames", ["HOH"])
    water.atoms.positions = [[0, 0, 0.1], [0, 0.76, -0.47], [0, -0.76, -0.47]]
    water.atoms.write(str(folder / "w.pdb"))
    with MDAnalysis.Writer(str(folder / "w.dcd"), 3) as writer:
        for _ in range(2):
            writer.write(water.atoms)
    molecule = ase.build.molecule("CH3CH2OH")
    molecule.center(vacuum=3.0)
    ase_io.write(folder / "big.pdb", molecule, format="proteindatabank")


def make(kind: str, folder: Path) -> tuple[str, list[str], str]:
    """The file of bad input ``kind`` in ``folder``: (its name, extra flags, the problem its
    line must say)."""
    if kind == "inf_xyz":
        (folder / "i.xyz").write_text("2\n\nO 0 0 0\nH 1 -inf 0\n")
        return "i.xyz", [], "position [1.0, -inf, 0.0] is not finite"
    if kind == "nan_dump":
        rows = "1 1 0 0 0\n2 1 nan 1 1\n"
        (folder / "n.lammpstrj").write_text(
            DUMP_HEAD.format(n=2) + "ITEM: ATOMS id type x y z\n" + rows
        )
        return "n.lammpstrj", [], "particle 1: position [nan, 1.0, 1.0] is not finite"
    if kind == "negative_radius":
        rows = "1 1 0 0 0 0.5\n2 1 1 1 1 -0.25\n"
        (folder / "r.lammpstrj").write_text(
            DUMP_HEAD.format(n=2) + "ITEM: ATOMS id type x y z radius\n" + rows
        )
        return "r.lammpstrj", [], "particle 1: radius -0.25 is not positive"
    if kind == "zero_radius_flag":
        (folder / "z.xyz").write_text("1\n\nO 0 0 0\n")
        return "z.xyz", ["--radius", "0"], "--radius: expected a positive number"
    if kind == "huge_xyz":
        (folder / "h.xyz").write_text("1000000000000\n\nO 0 0 0\n")
        return "h.xyz", [], "would need ~160,000 GB of memory"
    if kind == "huge_gro":
        (folder / "h.gro").write_text(
            "t\n1000000000000\n    1SOL     OW    1   0.126   1.624   1.679\n   1.0   1.0   1.0\n"
        )
        return "h.gro", [], "would need ~160,000 GB of memory"
    if kind == "huge_data":
        (folder / "h.data").write_text(DATA.format(n=1000000000000))
        return "h.data", [], "would need ~160,000 GB of memory"
    if kind == "short_data":
        (folder / "s.data").write_text(DATA.format(n=3))
        return "s.data", [], "claims 3 particles but the file holds 1"
    if kind == "truncated_xyz":
        (folder / "t.xyz").write_text("3\n\nO 0 0 0\nH 1 0 0\n")
        return "t.xyz", [], "t.xyz"
    if kind == "count_mismatch":
        water_trajectory(folder)
        problem = "frames hold 3 atoms but the topology big.pdb has 9"
        return "w.dcd", ["--topology", "big.pdb"], problem
    if kind == "past_end_dcd":
        water_trajectory(folder)
        return "w.dcd", ["--topology", "w.pdb", "--frame", "2"], "frame 2: past the end"
    if kind == "empty_pdb":
        (folder / "e.pdb").write_text("")
        return "e.pdb", [], "the file is empty"
    if kind == "empty_gsd":
        (folder / "e.gsd").write_bytes(b"")
        return "e.gsd", [], "the file is empty"
    raise AssertionError(kind)


DATA = (
    "LAMMPS data\n\n{n} atoms\n1 atom types\n\n0 10 xlo xhi\n0 10 ylo yhi\n0 10 zlo zhi\n\n"
    "Atoms # atomic\n\n1 1 1.0 2.0 3.0\n"
)
KINDS = [
    "inf_xyz",
    "nan_dump",
    "negative_radius",
    "zero_radius_flag",
    "huge_xyz",
    "huge_gro",
    "huge_data",
    "short_data",
    "truncated_xyz",
    "count_mismatch",
    "past_end_dcd",
    "empty_pdb",
    "empty_gsd",
]


@pytest.mark.parametrize("kind", KINDS)
def test_bad_particle_file_one_line_exit_2_output_kept(tmp_path, kind):
    name, extra, problem = make(kind, tmp_path)
    (tmp_path / "o.png").write_bytes(KEPT)
    done = run(
        "render",
        name,
        "-o",
        "o.png",
        "--overwrite",
        "--width",
        "16",
        "--height",
        "16",
        *extra,
        cwd=tmp_path,
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert problem in lines[0], lines[0]
    if kind != "zero_radius_flag":  # a flag's problem names the flag
        assert name in lines[0], lines[0]
    assert (tmp_path / "o.png").read_bytes() == KEPT
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".png") == ["o.png"]


def test_count_mismatch_names_the_trajectory_and_both_counts(tmp_path):
    """The trajectory's atom count against its topology's: the line names the trajectory."""
    name, extra, _ = make("count_mismatch", tmp_path)
    done = run("info", name, *extra, cwd=tmp_path)
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert "w.dcd" in line and "3" in line and "9" in line, line


def test_unknown_element_default_colour_and_one_warning(tmp_path):
    (tmp_path / "u.xyz").write_text("4\n\nQq 0 0 0\nQq 2 0 0\nZz 0 2 0\nO 0 0 2\n")
    done = run(
        "render",
        "u.xyz",
        "-o",
        "u.png",
        "--width",
        "24",
        "--height",
        "16",
        "--spp",
        "1",
        "--quiet",
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    warnings = [line for line in done.stderr.splitlines() if "unknown element" in line]
    assert len(warnings) == 1 and "'Qq'" in warnings[0] and "'Zz'" in warnings[0], done.stderr
    from PIL import Image

    image = np.asarray(Image.open(tmp_path / "u.png"))
    assert image.shape == (16, 24, 3)
