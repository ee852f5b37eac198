"""LAMMPS dumps of a general triclinic box (``ITEM: BOX BOUNDS abc origin``: each line one cell
vector and one coordinate of the origin), the form OVITO's LAMMPS dump exporter writes even for
an orthogonal cell: the cell and the positions read back as written."""

from __future__ import annotations

import numpy as np
import pytest

from embree_rt.scene.particles import ParticleFileError, read_particles

CELL = np.array([[10.0, 0.5, 0.0], [1.5, 9.0, 0.25], [-0.5, 1.0, 8.0]])
ORIGIN = np.array([-5.0, 2.0, 0.5])


def write_general_dump(path, columns: list[str], table: np.ndarray, box_lines: str) -> None:
    with open(path, "w") as out:
        out.write(f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{len(table)}\n")
        out.write("ITEM: BOX BOUNDS abc origin pp pp pp\n" + box_lines)
        out.write("ITEM: ATOMS " + " ".join(columns) + "\n")
        np.savetxt(out, table, fmt="%.9g")


def box_lines(cell: np.ndarray, origin: np.ndarray) -> str:
    return "".join(f"{a} {b} {c} {o}\n" for (a, b, c), o in zip(cell, origin, strict=True))


def test_cell_origin_and_positions_as_written(tmp_path):
    rng = np.random.default_rng(5)
    fractions = np.round(rng.uniform(0, 1, (40, 3)), 6)
    positions = ORIGIN + fractions @ CELL  # float64 reference
    ids = np.arange(1, 41)[:, None]
    plain = tmp_path / "plain.dump"
    write_general_dump(
        plain, ["id", "x", "y", "z"], np.hstack([ids, positions]), box_lines(CELL, ORIGIN)
    )
    frame = read_particles(plain)
    np.testing.assert_array_equal(frame.box, CELL)
    np.testing.assert_array_equal(frame.origin, ORIGIN)
    np.testing.assert_allclose(
        frame.positions, positions, rtol=0, atol=1e-7 * np.abs(positions).max()
    )  # %.9g
    scaled = tmp_path / "scaled.dump"
    write_general_dump(
        scaled, ["id", "xs", "ys", "zs"], np.hstack([ids, fractions]), box_lines(CELL, ORIGIN)
    )
    np.testing.assert_allclose(
        read_particles(scaled).positions, positions, rtol=0, atol=1e-12 * np.abs(positions).max()
    )


def test_general_box_of_three_numbers_a_line_refused(tmp_path):
    path = tmp_path / "bad.dump"
    write_general_dump(path, ["id", "x", "y", "z"], np.array([[1, 0.0, 0.0, 0.0]]), "0 10 0\n" * 3)
    with pytest.raises(
        ParticleFileError, match=r"bad\.dump.*'abc origin' box bounds are not 3 lines of 4"
    ):
        read_particles(path)
