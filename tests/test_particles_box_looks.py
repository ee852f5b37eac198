"""Particle files' simulation box (``--box``), RGB colour columns and a material per type:
the box's 12 edges against each reader library's own cell, a ray at an edge hitting it where
float64 says; colours from the file's columns in either range; materials by type."""

from __future__ import annotations

import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from tolerances import position_atol

ase_io = pytest.importorskip("ase.io")
import ase  # noqa: E402
import ase.io.lammpsrun  # noqa: E402
import gsd.hoomd  # noqa: E402
import MDAnalysis  # noqa: E402
from MDAnalysis.lib.mdamath import triclinic_vectors  # noqa: E402

from embree_rt.geometry import SceneGeometry  # noqa: E402
from embree_rt.scene.model import Scene  # noqa: E402
from embree_rt.scene.particles import ParticleFileError, ParticleLook, read_particles  # noqa: E402
from embree_rt.scene.particles.box import box_edges  # noqa: E402
from embree_rt.scene.particles.look import particle_look  # noqa: E402
from embree_rt.scene.particles.to_scene import UP_ROTATIONS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TRICLINIC = np.array([[6.0, 0.0, 0.0], [1.5, 5.0, 0.0], [-1.0, 0.8, 7.0]])


def reference_edges(cell: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(12, 2, 3) float64: the parallelepiped's edges, the pairs of its 8 corners whose
    (i, j, k) differ in one index (independent of ``box_edges``' construction)."""
    corners = {
        ijk: origin + np.asarray(ijk, np.float64) @ cell
        for ijk in itertools.product((0, 1), repeat=3)
    }
    edges = [
        (corners[a], corners[b])
        for a, b in itertools.combinations(corners, 2)
        if sum(x != y for x, y in zip(a, b, strict=True)) == 1
    ]
    assert len(edges) == 12
    return np.array(edges)


def assert_same_edges(drawn: np.ndarray, expected: np.ndarray, atol: float) -> None:
    """Each of the 12 ``drawn`` (12, 2, 3) edges is one of ``expected``'s, either way round,
    within ``atol``, and each expected edge is drawn once."""
    forward = np.abs(drawn[:, None] - expected[None]).max(axis=(2, 3))
    backward = np.abs(drawn[:, None] - expected[None, :, ::-1]).max(axis=(2, 3))
    distance = np.minimum(forward, backward)
    match = distance.argmin(axis=1)
    assert sorted(match.tolist()) == list(range(12))
    assert distance.min(axis=1).max() <= atol


def drawn_edges(scene: Scene) -> np.ndarray:
    """(12, 2, 3) the scene's box curves as edges in the file's axes (z up undone)."""
    (curves,) = scene.curves
    points = curves.points.astype(np.float64) @ UP_ROTATIONS["z"]  # world -> file: R^-1 = R^T
    return np.stack([points[curves.starts], points[curves.starts + 1]], axis=1)


def triclinic_atoms() -> ase.Atoms:
    fractions = np.random.default_rng(11).uniform(0.3, 0.7, (6, 3))
    return ase.Atoms("Cu2O2H2", scaled_positions=fractions, cell=TRICLINIC, pbc=True)


def assert_box_is(path: Path, cell: np.ndarray, origin: np.ndarray) -> None:
    scene = Scene.from_particles(path, box=True, floor=False)
    expected = reference_edges(cell, origin)
    # float32 curve points: a few ulps of the box's coordinates
    assert_same_edges(drawn_edges(scene), expected, position_atol(expected, ulps=2))


def test_box_of_extended_xyz_is_ases_cell(tmp_path):
    path = tmp_path / "t.xyz"
    ase_io.write(path, triclinic_atoms(), format="extxyz")
    cell = np.asarray(ase_io.read(path).cell[:], np.float64)
    assert_box_is(path, cell, np.zeros(3))


def test_box_of_pdb_is_mdanalysis_dimensions(tmp_path):
    path = tmp_path / "t.pdb"
    ase_io.write(path, triclinic_atoms(), format="proteindatabank")
    universe = MDAnalysis.Universe(str(path))
    assert not np.allclose(universe.dimensions[3:], 90.0)  # a triclinic CRYST1
    cell = triclinic_vectors(universe.dimensions).astype(np.float64)
    assert_box_is(path, cell, np.zeros(3))


def test_box_of_gsd_with_tilts(tmp_path):
    path = tmp_path / "t.gsd"
    lx, ly, lz, xy, xz, yz = 6.0, 5.0, 7.0, 0.3, -0.2, 0.1
    with gsd.hoomd.open(str(path), "w") as trajectory:
        snapshot = gsd.hoomd.Frame()
        snapshot.particles.N = 2
        snapshot.particles.position = np.array([[0, 0, 0], [1, 1, 1]], np.float32)
        snapshot.particles.types = ["A"]
        snapshot.particles.typeid = [0, 0]
        snapshot.configuration.box = [lx, ly, lz, xy, xz, yz]
        trajectory.append(snapshot)
    with gsd.hoomd.open(str(path), "r") as trajectory:
        box = trajectory[0].configuration.box
    # HOOMD's box: a1 = (Lx, 0, 0), a2 = (xy Ly, Ly, 0), a3 = (xz Lz, yz Lz, Lz), centred on 0
    cell = np.array(
        [[box[0], 0, 0], [box[3] * box[1], box[1], 0], [box[4] * box[2], box[5] * box[2], box[2]]],
        np.float64,
    )
    assert_box_is(path, cell, -cell.sum(axis=0) / 2)


def test_box_of_triclinic_lammps_dump_is_ases_reading(tmp_path):
    """A dump with ``xy xz yz`` written by hand (no library writes one), its cell and origin
    as ASE's own LAMMPS dump reader takes them."""
    xlo, xhi, ylo, yhi, zlo, zhi, xy, xz, yz = -1.0, 5.0, 0.5, 5.5, 2.0, 9.0, 1.5, -1.0, 0.8
    bounds = [
        (xlo + min(0, xy, xz, xy + xz), xhi + max(0, xy, xz, xy + xz), xy),
        (ylo + min(0, yz), yhi + max(0, yz), xz),
        (zlo, zhi, yz),
    ]
    path = tmp_path / "t.lammpstrj"
    rows = "1 1 1.0 2.0 4.0\n2 2 2.0 3.0 5.0\n"
    path.write_text(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS xy xz yz pp pp pp\n"
        + "".join(f"{a} {b} {c}\n" for a, b, c in bounds)
        + "ITEM: ATOMS id type x y z\n"
        + rows
    )
    with open(path) as handle:
        atoms = ase.io.lammpsrun.read_lammps_dump_text(handle, index=0)
    cell = np.asarray(atoms.cell[:], np.float64)
    np.testing.assert_allclose(cell, [[6, 0, 0], [xy, 5, 0], [xz, yz, 7]], atol=1e-12)
    origin = np.asarray(atoms.get_celldisp(), np.float64).reshape(3)
    np.testing.assert_allclose(origin, [xlo, ylo, zlo], atol=1e-12)
    assert_box_is(path, cell, origin)


def test_box_edges_are_the_twelve_edges():
    edges = box_edges(TRICLINIC, np.ones(3)).reshape(12, 2, 3)
    assert_same_edges(edges, reference_edges(TRICLINIC, np.ones(3)), 1e-12)


def test_a_ray_at_an_edge_hits_it(tmp_path):
    """Rays toward each edge's midpoint from outside the box, perpendicular to the edge: each
    hits the round curve at (distance - radius) (float64 closed form)."""
    path = tmp_path / "t.xyz"
    ase_io.write(path, triclinic_atoms(), format="extxyz")
    scene = Scene.from_particles(path, box=True, floor=False, look=ParticleLook(radius=0.2))
    (curves,) = scene.curves
    points = curves.points.astype(np.float64)
    radius = float(curves.radii[0])
    center = points.mean(axis=0)
    starts, ends = points[curves.starts], points[curves.starts + 1]
    middles = (starts + ends) / 2
    along = (ends - starts) / np.linalg.norm(ends - starts, axis=1)[:, None]
    outward = middles - center
    outward -= np.einsum("ij,ij->i", outward, along)[:, None] * along
    outward /= np.linalg.norm(outward, axis=1)[:, None]
    distance = 20.0
    origins = middles + distance * outward
    with SceneGeometry(scene) as geometry:
        hits = geometry.intersect(
            np.ascontiguousarray(origins.T, np.float32),
            np.ascontiguousarray(-outward.T, np.float32),
        )
    assert hits.hit.all()
    atol = position_atol(origins, ulps=64)  # a cone solved in float32, as tests/test_curves.py
    np.testing.assert_allclose(hits.t, distance - radius, rtol=0, atol=atol)


def test_no_box_in_the_file_is_refused(tmp_path):
    path = tmp_path / "m.xyz"
    path.write_text("2\n\nO 0 0 0\nH 1 0 0\n")
    with pytest.raises(ParticleFileError, match=r"m\.xyz: --box: the file gives no simulation box"):
        Scene.from_particles(path, box=True)


# -- colours from RGB columns ------------------------------------------------------------------


def test_extended_xyz_color_array_in_0_1(tmp_path):
    atoms = triclinic_atoms()
    rgb = np.random.default_rng(2).uniform(0, 1, (len(atoms), 3))
    atoms.set_array("color", rgb)
    path = tmp_path / "c.xyz"
    ase_io.write(path, atoms, format="extxyz")
    frame = read_particles(path)
    expected = ase_io.read(path).get_array("color")
    colors, _ = particle_look(frame, ParticleLook(color_columns=("color",)))
    np.testing.assert_array_equal(colors, np.rint(expected * 255).astype(np.uint8))


def test_dump_rgb_columns_in_0_255_and_out_of_range(tmp_path):
    path = tmp_path / "c.lammpstrj"
    rgb = np.array([[255, 0, 10], [3, 128, 200], [0, 0, 1]])
    rows = "".join(f"{i + 1} 1 {i} 0 0 {r} {g} {b}\n" for i, (r, g, b) in enumerate(rgb))
    header = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS pp pp pp\n"
    columns = "ITEM: ATOMS id type x y z c_rgb[1] c_rgb[2] c_rgb[3]\n"
    path.write_text(header + "0 4\n" * 3 + columns + rows)
    frame = read_particles(path)
    names = ("c_rgb[1]", "c_rgb[2]", "c_rgb[3]")
    colors, _ = particle_look(frame, ParticleLook(color_columns=names))
    np.testing.assert_array_equal(colors, rgb.astype(np.uint8))  # a value above 1: 0..255
    path.write_text(header + "0 4\n" * 3 + columns + rows.replace("255 0 10", "256 0 10"))
    with pytest.raises(ParticleFileError, match=r"particle 0: colour \[256.0, 0.0, 10.0\]"):
        particle_look(read_particles(path), ParticleLook(color_columns=names))
    with pytest.raises(ParticleFileError, match="--color-columns: give it or --color"):
        particle_look(frame, ParticleLook(color_columns=names, color_by="type"))
    with pytest.raises(ParticleFileError, match="no column 'blue'"):
        particle_look(frame, ParticleLook(color_columns=("c_rgb[1]", "c_rgb[2]", "blue")))


def test_color_columns_in_a_scene_file_and_on_the_command_line(tmp_path):
    from embree_rt.scene.loader import load_scene

    atoms = triclinic_atoms()
    rgb = np.random.default_rng(9).uniform(0, 1, (len(atoms), 3))
    atoms.set_array("color", rgb)
    ase_io.write(tmp_path / "c.xyz", atoms, format="extxyz")
    expected = np.rint(ase_io.read(tmp_path / "c.xyz").get_array("color") * 255).astype(np.uint8)
    for value in ('"color"', '["color_x", "color_y", "color_z"]'):
        (tmp_path / "s.toml").write_text(
            f'[[particles]]\nfile = "c.xyz"\ncolor_columns = {value}\n'
        )
        np.testing.assert_array_equal(load_scene(tmp_path / "s.toml").sphere_colors, expected)
    (tmp_path / "s.toml").write_text('[[particles]]\nfile = "c.xyz"\ncolor_columns = ["a", "b"]\n')
    with pytest.raises(ParticleFileError.__mro__[1], match="color_columns: expected 3 column"):
        load_scene(tmp_path / "s.toml")
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "embree_rt",
            "render",
            "c.xyz",
            "-o",
            "o.png",
            "--color-columns",
            "colour",
            "--width",
            "16",
            "--height",
            "16",
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "embree-rt: error: c.xyz: --color-columns: no column 'colour_x' in the file (it has: "
        "color_x, color_y, color_z)"
    ]
    assert not (tmp_path / "o.png").exists()


# -- a material per type -----------------------------------------------------------------------


def write_two_types(path: Path) -> None:
    rows = "".join(f"{i + 1} {1 + i % 2} {2 * i} 0 0\n" for i in range(6))
    path.write_text(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n6\nITEM: BOX BOUNDS pp pp pp\n"
        + "0 12\n" * 3
        + "ITEM: ATOMS id type x y z\n"
        + rows
    )


def test_material_per_type_in_python_and_a_scene_file(tmp_path):
    from embree_rt.scene.loader import load_scene

    path = tmp_path / "d.lammpstrj"
    write_two_types(path)
    scene = Scene.from_particles(path, materials={"2": "mirror"})
    names = np.asarray(scene.material_names)[scene.sphere_materials]
    assert names.tolist() == ["matte", "mirror"] * 3
    (tmp_path / "s.toml").write_text(
        '[[particles]]\nfile = "d.lammpstrj"\nbox = true\nmaterials = { 1 = "glass" }\n'
    )
    loaded = load_scene(tmp_path / "s.toml")
    names = np.asarray(loaded.material_names)[loaded.sphere_materials]
    assert names.tolist() == ["glass", "matte"] * 3
    assert len(loaded.curves) == 1 and len(loaded.curves[0]) == 12
    with pytest.raises(ParticleFileError, match=r"no particle of type '3'"):
        Scene.from_particles(path, materials={"3": "mirror"})
    (tmp_path / "s.toml").write_text(
        '[[particles]]\nfile = "d.lammpstrj"\nmaterials = { 1 = "unobtainium" }\n'
    )
    with pytest.raises(ParticleFileError.__mro__[1], match=r"materials\.1: undefined material"):
        load_scene(tmp_path / "s.toml")


def test_command_line_box_material_and_colour_columns(tmp_path):
    path = tmp_path / "d.lammpstrj"
    write_two_types(path)
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    flags = ["--width", "32", "--height", "24", "--spp", "1", "--quiet"]

    def render(output: str, *given: str) -> subprocess.CompletedProcess:
        command = [sys.executable, "-m", "embree_rt", "render", "d.lammpstrj", "-o", output]
        return subprocess.run(
            [*command, *given, *flags], cwd=tmp_path, env=env, capture_output=True, text=True
        )

    done = render("o.png", "--box", "--material-of", "2=mirror")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "o.png").stat().st_size > 0
    done = render("p.png", "--material-of", "2")
    assert done.returncode == 2 and "expected TYPE=MATERIAL" in done.stderr
    assert not (tmp_path / "p.png").exists()
