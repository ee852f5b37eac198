"""Particle files: each format written by its library's own writer (or by hand where none
writes it), read back against the library's own positions; spheres of the stated radii hit
where float64 says; colours by element, type and property; bad input refused in one line."""

from __future__ import annotations

import bz2
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from particle_samples import MOL2
from tolerances import position_atol

ase_io = pytest.importorskip("ase.io")
import ase.build  # noqa: E402
import gsd.hoomd  # noqa: E402
import matplotlib  # noqa: E402
import MDAnalysis  # noqa: E402
from ase.data import atomic_numbers  # noqa: E402
from ase.data.colors import jmol_colors  # noqa: E402

from embree_rt.geometry import SceneGeometry  # noqa: E402
from embree_rt.scene.model import Scene  # noqa: E402
from embree_rt.scene.particles import ParticleFileError, read_particles  # noqa: E402
from embree_rt.scene.particles.look import ParticleLook, particle_look  # noqa: E402
from embree_rt.textures import SRGB8_TO_LINEAR  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def molecule() -> ase.Atoms:
    atoms = ase.build.molecule("CH3CH2OH")
    atoms.center(vacuum=3.0)
    return atoms


def write_dump(path: Path, frames: list[dict], columns: list[str], box=(0.0, 10.0)) -> None:
    """A LAMMPS text dump by hand (no library writes one): ``frames`` of column -> values."""
    with open(path, "w") as out:
        for step, frame in enumerate(frames):
            count = len(frame[columns[0]])
            out.write(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{count}\n")
            out.write("ITEM: BOX BOUNDS pp pp pp\n" + f"{box[0]} {box[1]}\n" * 3)
            out.write("ITEM: ATOMS " + " ".join(columns) + "\n")
            for i in range(count):
                out.write(" ".join(str(frame[c][i]) for c in columns) + "\n")


def dump_frames(count: int = 50, frames: int = 2, seed: int = 3) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    for step in range(frames):
        out.append(
            {
                "id": np.arange(1, count + 1),
                "type": rng.integers(1, 4, count),
                "x": np.round(rng.uniform(0, 10, count), 6),
                "y": np.round(rng.uniform(0, 10, count), 6),
                "z": np.round(rng.uniform(0, 10, count) + step, 6),
                "vx": np.round(rng.normal(size=count), 6),
                "radius": np.round(rng.uniform(0.2, 0.6, count), 6),
            }
        )
    return out


# -- formats against the libraries' own readers ------------------------------------------------


@pytest.mark.parametrize(
    ("name", "fmt"), [("m.xyz", "extxyz"), ("POSCAR", "vasp"), ("m.cif", "cif")]
)
def test_ase_formats_match_ase(tmp_path, name, fmt):
    atoms = molecule()
    path = tmp_path / name
    ase_io.write(path, atoms, format=fmt)
    expected = ase_io.read(path, format=fmt)
    frame = read_particles(path)
    assert len(frame) == len(expected)
    np.testing.assert_array_equal(frame.positions, expected.get_positions())
    assert list(frame.elements) == expected.get_chemical_symbols()


def test_extended_xyz_frames_differ(tmp_path):
    first, second = molecule(), molecule()
    second.positions += 1.5
    path = tmp_path / "m.xyz"
    ase_io.write(path, [first, second], format="extxyz")
    frames = [read_particles(path, frame=k) for k in (0, 1)]
    assert frames[0].frame_count == 2
    np.testing.assert_allclose(frames[1].positions - frames[0].positions, 1.5, atol=1e-9)


def test_mol2_by_hand_matches_mdanalysis(tmp_path):
    path = tmp_path / "w.mol2"
    path.write_text(MOL2)  # MDAnalysis writes MOL2 only of MOL2 it read
    frame = read_particles(path)
    expected = MDAnalysis.Universe(str(path)).atoms.positions
    np.testing.assert_array_equal(frame.positions, expected.astype(np.float64))
    assert list(frame.elements) == ["O", "H", "H"]


@pytest.mark.parametrize("suffix", [".pdb", ".gro", ".pqr"])
def test_mdanalysis_formats_match_mdanalysis(tmp_path, suffix):
    pdb = tmp_path / "m.pdb"
    ase_io.write(pdb, molecule())
    universe = MDAnalysis.Universe(str(pdb))
    path = tmp_path / f"m{suffix}"
    universe.atoms.write(str(path))
    expected = MDAnalysis.Universe(str(path)).atoms.positions
    frame = read_particles(path)
    assert len(frame) == len(expected)
    np.testing.assert_array_equal(frame.positions, expected.astype(np.float64))
    assert list(frame.elements) == molecule().get_chemical_symbols()
    if suffix == ".pqr":
        assert frame.radii is not None


def test_trajectory_over_topology_and_count_mismatch(tmp_path):
    pdb = tmp_path / "m.pdb"
    ase_io.write(pdb, molecule())
    universe = MDAnalysis.Universe(str(pdb))
    dcd = tmp_path / "m.dcd"
    with MDAnalysis.Writer(str(dcd), len(universe.atoms)) as writer:
        for shift in (0.0, 2.0):
            universe.atoms.positions = MDAnalysis.Universe(str(pdb)).atoms.positions + shift
            writer.write(universe.atoms)
    frame = read_particles(dcd, frame=1, topology=pdb)
    expected = MDAnalysis.Universe(str(pdb), str(dcd))
    expected.trajectory[1]
    np.testing.assert_array_equal(frame.positions, expected.atoms.positions.astype(np.float64))
    assert frame.frame_count == 2
    with pytest.raises(ParticleFileError, match="--topology"):
        read_particles(dcd)
    other = tmp_path / "other.pdb"
    ase_io.write(other, ase.build.molecule("H2O"))
    with pytest.raises(ParticleFileError, match=r"m\.dcd"):
        read_particles(dcd, topology=other)


def test_gsd_frames_types_and_diameters(tmp_path):
    path = tmp_path / "p.gsd"
    rng = np.random.default_rng(5)
    positions = [rng.uniform(-4, 4, (30, 3)).astype(np.float32) for _ in range(2)]
    with gsd.hoomd.open(str(path), "w") as trajectory:
        for pos in positions:
            snapshot = gsd.hoomd.Frame()
            snapshot.particles.N = 30
            snapshot.particles.position = pos
            snapshot.particles.types = ["A", "B"]
            snapshot.particles.typeid = np.arange(30) % 2
            snapshot.particles.diameter = np.full(30, 0.8, np.float32)
            snapshot.configuration.box = [8, 8, 8, 0, 0, 0]
            trajectory.append(snapshot)
    frame = read_particles(path, frame=1)
    assert frame.frame_count == 2
    np.testing.assert_array_equal(frame.positions, positions[1].astype(np.float64))
    assert list(frame.types[:4]) == ["A", "B", "A", "B"]
    np.testing.assert_allclose(frame.radii, 0.4, rtol=1e-7)


def test_lammps_dump_columns_scaled_and_compressed(tmp_path):
    frames = dump_frames()
    columns = ["vx", "z", "type", "radius", "id", "x", "y"]  # any order
    path = tmp_path / "d.lammpstrj"
    write_dump(path, frames, columns)
    frame = read_particles(path, frame=1)
    assert frame.frame_count == 2
    expected = np.stack([frames[1][a] for a in "xyz"], axis=1)
    np.testing.assert_array_equal(frame.positions, expected)
    np.testing.assert_array_equal(frame.radii, frames[1]["radius"])
    np.testing.assert_array_equal(frame.properties["vx"], frames[1]["vx"])
    assert list(frame.types) == [str(t) for t in frames[1]["type"]]
    scaled = [{**f, "xs": f["x"] / 10, "ys": f["y"] / 10, "zs": f["z"] / 10} for f in frames]
    scaled_path = tmp_path / "s.dump"
    write_dump(scaled_path, scaled, ["id", "type", "xs", "ys", "zs"])
    np.testing.assert_allclose(read_particles(scaled_path).positions, frame_positions(frames[0]))
    packed = tmp_path / "d.lammpstrj.bz2"
    packed.write_bytes(bz2.compress(path.read_bytes()))
    np.testing.assert_array_equal(read_particles(packed, frame=1).positions, frame.positions)


def frame_positions(frame: dict) -> np.ndarray:
    return np.stack([frame[a] for a in "xyz"], axis=1)


def test_lammps_data_matches_mdanalysis(tmp_path):
    path = tmp_path / "p.data"
    path.write_text(
        "LAMMPS data\n\n3 atoms\n2 atom types\n\n0 10 xlo xhi\n0 10 ylo yhi\n0 10 zlo zhi\n\n"
        "Masses\n\n1 1.0\n2 2.0\n\nAtoms # atomic\n\n1 1 1.0 2.0 3.0\n2 2 4.0 5.0 6.0\n"
        "3 1 7.5 8.5 9.5\n"
    )
    frame = read_particles(path)
    expected = MDAnalysis.Universe(str(path), format="DATA", atom_style="id type x y z").atoms
    np.testing.assert_array_equal(frame.positions, expected.positions.astype(np.float64))
    assert list(frame.types) == ["1", "2", "1"]
    # no style comment: detected from the column count, as MDAnalysis's would be told
    path.write_text(path.read_text().replace("Atoms # atomic", "Atoms"))
    np.testing.assert_array_equal(read_particles(path).positions, frame.positions)
    sphere = tmp_path / "s.data"
    sphere.write_text(
        "LAMMPS data\n\n2 atoms\n2 atom types\n\n0 10 xlo xhi\n0 10 ylo yhi\n0 10 zlo zhi\n\n"
        "Atoms # sphere\n\n2 2 0.5 1.0 5.0 6.0 7.0\n1 1 1.5 1.0 2.0 3.0 4.0\n"
    )
    frame = read_particles(sphere)
    np.testing.assert_array_equal(frame.positions, [[2, 3, 4], [5, 6, 7]])
    np.testing.assert_array_equal(frame.radii, [0.75, 0.25])


# -- colours and sizes -------------------------------------------------------------------------


def test_colors_by_element_type_and_property(tmp_path):
    atoms = molecule()
    path = tmp_path / "m.xyz"
    ase_io.write(path, atoms)
    frame = read_particles(path)
    colors, radii = particle_look(frame, ParticleLook())
    numbers = [atomic_numbers[s] for s in atoms.get_chemical_symbols()]
    np.testing.assert_array_equal(colors, np.rint(jmol_colors[numbers] * 255).astype(np.uint8))
    from ase.data import vdw_radii

    np.testing.assert_array_equal(radii, vdw_radii[numbers])
    frames = dump_frames()
    dump = tmp_path / "d.lammpstrj"
    write_dump(dump, frames, ["id", "type", "x", "y", "z", "vx", "radius"])
    frame = read_particles(dump)
    colors, radii = particle_look(frame, ParticleLook(radius=0.3, radius_scale=2.0))
    tab10 = np.rint(np.asarray(matplotlib.colormaps["tab10"].colors) * 255).astype(np.uint8)
    np.testing.assert_array_equal(colors, tab10[frames[0]["type"] - 1])
    np.testing.assert_array_equal(radii, 0.6)
    look = ParticleLook(color_by="vx", colormap="viridis", value_range=(-1.0, 1.0))
    colors, radii = particle_look(frame, look)
    np.testing.assert_array_equal(radii, frames[0]["radius"])
    cmap = matplotlib.colormaps["viridis"]
    scaled = np.clip((frames[0]["vx"] + 1.0) / 2.0, 0, 1)
    np.testing.assert_array_equal(colors, np.rint(cmap(scaled)[:, :3] * 255).astype(np.uint8))
    with pytest.raises(ParticleFileError, match="no property 'vz'"):
        particle_look(frame, ParticleLook(color_by="vz"))


def test_unknown_element_warns_once(tmp_path):
    path = tmp_path / "u.xyz"
    path.write_text("3\n\nXx 0 0 0\nXx 1 0 0\nO 0 1 0\n")
    with pytest.warns(UserWarning, match="unknown element") as caught:
        scene = Scene.from_particles(path)
    assert len(caught) == 1
    assert len(scene.sphere_radii) == 3


@pytest.mark.parametrize("spheres", ["analytic", "point", "mesh"])
def test_hits_on_spheres_of_stated_radii_take_their_colors(tmp_path, spheres):
    """Rays down the renderer's -y onto each particle: the nearest hit of each (float64 brute
    force over all spheres, z up: file z is world y) and its colour."""
    frames = dump_frames(count=40)
    path = tmp_path / "d.lammpstrj"
    write_dump(path, frames, ["id", "type", "x", "y", "z", "vx", "radius"])
    scene = Scene.from_particles(path, look=ParticleLook(color_by="vx"), floor=False)
    frame = read_particles(path)
    world = np.stack([frame.positions[:, 0], frame.positions[:, 2], -frame.positions[:, 1]], 1)
    np.testing.assert_allclose(scene.sphere_centers, world, rtol=1e-7)
    origins = world + np.array([0.0, 50.0, 0.0])
    directions = np.tile([0.0, -1.0, 0.0], (len(world), 1))
    radii = frame.radii
    # float64 reference: the nearest of all spheres along each ray
    offset = origins[:, None, :] - world[None, :, :]
    b = np.einsum("rsk,rk->rs", offset, directions)
    c = np.einsum("rsk,rsk->rs", offset, offset) - radii[None, :] ** 2
    disc = b * b - c
    t = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    nearest = np.argmin(t, axis=1)
    t_ref = t[np.arange(len(world)), nearest]
    with SceneGeometry(scene, spheres=spheres) as geometry:
        hits = geometry.intersect(
            np.ascontiguousarray(origins.T, np.float32),
            np.ascontiguousarray(directions.T, np.float32),
        )
    assert hits.hit.all()
    if spheres != "mesh":  # icospheres only approximate the spheres
        np.testing.assert_allclose(hits.t, t_ref, rtol=0, atol=position_atol(60.0))
    colors = np.full((3, len(world)), np.nan, np.float32)
    colors[:, hits.colored] = hits.color
    expected = SRGB8_TO_LINEAR[scene.sphere_colors[nearest]].T
    np.testing.assert_array_equal(colors, expected)


def test_wrap_up_axis_and_select_on_a_dump(tmp_path):
    frames = dump_frames(count=30)
    frames[0]["x"][:3] = [12.5, -0.5, 25.0]  # outside the 0..10 box
    write_dump(tmp_path / "d.lammpstrj", frames, ["id", "type", "x", "y", "z"])
    frame = read_particles(tmp_path / "d.lammpstrj")
    from embree_rt.scene.particles.to_scene import particle_spheres

    centers, _, _, _ = particle_spheres(frame, up="x", wrap=True)
    wrapped = frame_positions(frames[0]) % 10.0  # float64 reference of the periodic image
    # x up: file (x, y, z) is world (y, x, -z)
    expected = np.stack([wrapped[:, 1], wrapped[:, 0], -wrapped[:, 2]], axis=1)
    np.testing.assert_allclose(centers, expected, rtol=0, atol=1e-12)
    assert np.all((wrapped >= 0) & (wrapped < 10))
    kept, _, _, _ = particle_spheres(frame, up="y", select="type 2 3")
    mask = frames[0]["type"] != 1
    np.testing.assert_array_equal(kept, frame_positions(frames[0])[mask])
    with pytest.raises(ParticleFileError, match="keeps no particles"):
        particle_spheres(frame, select="type 7")


def test_add_spheres_colors_and_add_particles_from_ase():
    scene = Scene()
    scene.add_spheres([[0, 0, 0]], [1.0], "matte")
    scene.add_spheres([[3, 0, 0], [6, 0, 0]], [1.0, 1.0], "matte", colors=[[1, 0, 0], [0, 0, 1]])
    assert scene.sphere_colors.dtype == np.uint8
    np.testing.assert_array_equal(scene.sphere_colors[1:], [[255, 0, 0], [0, 0, 255]])
    scene.add_particles(molecule())
    assert scene.sphere_colors.shape == (3 + len(molecule()), 3)
    with pytest.raises(ValueError, match="colors"):
        scene.add_spheres([[0, 0, 0]], [1.0], "matte", colors=[[2.0, 0, 0]])


def test_sphere_array_colors_in_a_scene_file_and_written_back(tmp_path):
    from embree_rt.scene.loader import load_scene
    from embree_rt.scene.writer import save_scene

    colors = np.array([[255, 0, 0], [0, 128, 255]], np.uint8)
    np.savez(tmp_path / "s.npz", centers=[[0, 0, 0], [3, 0, 0]], radii=[1, 1], colors=colors)
    (tmp_path / "scene.toml").write_text('[[sphere_arrays]]\nfile = "s.npz"\n')
    scene = load_scene(tmp_path / "scene.toml")
    np.testing.assert_array_equal(scene.sphere_colors, colors)
    save_scene(scene, tmp_path / "again.toml")
    np.testing.assert_array_equal(load_scene(tmp_path / "again.toml").sphere_colors, colors)
    np.savez(tmp_path / "s.npz", centers=[[0, 0, 0], [3, 0, 0]], radii=[1, 1], colors=[[2, 0, 0]])
    with pytest.raises(ParticleFileError.__mro__[1], match="colors"):
        load_scene(tmp_path / "scene.toml")


def test_particles_entry_in_a_scene_file(tmp_path):
    from embree_rt.errors import InputError
    from embree_rt.scene.loader import load_scene

    frames = dump_frames(count=20)
    write_dump(tmp_path / "d.lammpstrj", frames, ["id", "type", "x", "y", "z", "vx", "radius"])
    (tmp_path / "scene.toml").write_text(
        "[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\n\n"
        '[[particles]]\nfile = "d.lammpstrj"\nframe = 1\nup = "y"\ncolor_by = "vx"\n'
        'range = [-1, 1]\nradius_scale = 2.0\nmaterial = "mirror"\n'
    )
    scene = load_scene(tmp_path / "scene.toml")
    assert len(scene.sphere_radii) == 21
    np.testing.assert_allclose(scene.sphere_centers[1:], frame_positions(frames[1]), rtol=1e-7)
    np.testing.assert_allclose(scene.sphere_radii[1:], 2.0 * frames[1]["radius"], rtol=1e-7)
    assert set(scene.sphere_materials[1:]) == {scene.material_index("mirror")}
    expected = particle_look(
        read_particles(tmp_path / "d.lammpstrj", frame=1),
        ParticleLook(color_by="vx", value_range=(-1.0, 1.0)),
    )[0]
    np.testing.assert_array_equal(scene.sphere_colors[1:], expected)
    (tmp_path / "scene.toml").write_text('[[particles]]\nfile = "d.lammpstrj"\nframe = 5\n')
    with pytest.raises(InputError, match=r"scene\.toml: particles\[0\]\.file: .*past the end"):
        load_scene(tmp_path / "scene.toml")


def test_gallery_particle_files_are_what_the_script_makes(tmp_path):
    """The files in assets/ read as the ones assets/make_particles.py makes now (compared by
    what they hold, not by bytes: writers may lay the same values out differently)."""
    done = subprocess.run(
        [sys.executable, str(ROOT / "assets" / "make_particles.py"), str(tmp_path)],
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    for name in ("helix.pdb", "peptide.pdb", "membrane.gsd", "packing.lammpstrj"):
        made, kept = read_particles(tmp_path / name), read_particles(ROOT / "assets" / name)
        np.testing.assert_array_equal(made.positions, kept.positions)
        assert list(made.labels()[1]) == list(kept.labels()[1])
        for key, values in made.properties.items():
            np.testing.assert_array_equal(values, kept.properties[key])
        made_bonds, kept_bonds = (
            np.zeros((0, 2)) if f.bonds is None else f.bonds for f in (made, kept)
        )
        np.testing.assert_array_equal(made_bonds, kept_bonds)


# -- the command line and bad input ------------------------------------------------------------


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args], cwd=cwd, env=env, capture_output=True, text=True
    )


def test_render_and_info_of_a_dump(tmp_path):
    frames = dump_frames()
    write_dump(tmp_path / "d.lammpstrj", frames, ["id", "type", "x", "y", "z", "vx"])
    done = run("info", "d.lammpstrj", "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    import json

    summary = json.loads(done.stdout)
    assert summary["particles"] == 50 and summary["frames"] == 2
    assert sum(summary["types"].values()) == 50
    done = run(
        "render",
        "d.lammpstrj",
        "-o",
        "o.png",
        "--width",
        "64",
        "--height",
        "48",
        "--spp",
        "1",
        "--quiet",
        "--select",
        "type 1",
        "-D",
        "render.seed=2",
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "o.png").stat().st_size > 0


BAD = {
    "truncated": ("t.lammpstrj", "truncated"),
    "nan": ("n.xyz", "not finite"),
    "zero_radius": ("r.lammpstrj", "not positive"),
    "huge": ("h.lammpstrj", "would need"),
    "past_end": ("p.lammpstrj", "past the end"),
    "empty": ("e.xyz", "empty"),
}


def make_bad(kind: str, path: Path) -> list[str]:
    frames = dump_frames(count=5, frames=1)
    columns = ["id", "type", "x", "y", "z", "radius"]
    if kind in ("truncated", "zero_radius", "huge", "past_end"):
        if kind == "zero_radius":
            frames[0]["radius"][2] = 0.0
        write_dump(path, frames, columns)
        text = path.read_text()
        if kind == "truncated":
            path.write_text(text[: text.rindex("\n", 0, len(text) - 1)])
        if kind == "huge":
            path.write_text(
                text.replace("ITEM: NUMBER OF ATOMS\n5\n", "ITEM: NUMBER OF ATOMS\n1000000000000\n")
            )
        if kind == "past_end":
            return ["--frame", "3"]
    elif kind == "nan":
        path.write_text("2\n\nO 0 0 0\nH nan 0 0\n")
    elif kind == "empty":
        path.write_text("")
    return []


@pytest.mark.parametrize("kind", sorted(BAD))
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, kind):
    name, problem = BAD[kind]
    extra = make_bad(kind, tmp_path / name)
    done = run(
        "render", name, "-o", "o.png", "--width", "16", "--height", "16", *extra, cwd=tmp_path
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and name in lines[0] and problem in lines[0], done.stderr
    assert not (tmp_path / "o.png").exists()


def test_trajectory_frames_each_an_image_on_disk_skipped(tmp_path):
    write_dump(
        tmp_path / "d.lammpstrj", dump_frames(count=40, frames=3), ["id", "type", "x", "y", "z"]
    )
    flags = ["--width", "48", "--height", "32", "--spp", "1", "--quiet"]
    done = run(
        "render", "d.lammpstrj", "-o", "s/f_{frame}.png", "--frames", "0:3:2", *flags, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["f_0.png", "f_2.png"]
    from PIL import Image

    first, last = (np.asarray(Image.open(tmp_path / "s" / f"f_{k}.png")) for k in (0, 2))
    assert np.any(first != last)  # the particles moved; the camera stayed
    before = (tmp_path / "s" / "f_0.png").stat().st_mtime_ns
    done = run(
        "render", "d.lammpstrj", "-o", "s/f_{frame}.png", "--frames", "0:2", *flags, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "s" / "f_0.png").stat().st_mtime_ns == before  # on disk: skipped
    assert (tmp_path / "s" / "f_1.png").exists()
    done = run(
        "render", "d.lammpstrj", "-o", "t/f_{frame}.png", "--frames", "1:9", *flags, cwd=tmp_path
    )
    assert done.returncode == 2
    assert "d.lammpstrj: --frames: '1:9'" in done.stderr and not (tmp_path / "t").exists()


def test_particle_flags_refused_for_a_scene_file(tmp_path):
    scene = ROOT / "scenes" / "three_spheres.toml"
    done = run("info", str(scene), "--color-by", "vx", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"embree-rt: error: --color-by: only for particle files, and {scene} is not one"
    ]


def test_without_the_extra_one_line_naming_it(tmp_path):
    ase_io.write(tmp_path / "m.pdb", molecule())
    code = (
        "import sys; sys.modules['MDAnalysis'] = None; "
        "from embree_rt.cli import main; sys.exit(main(['info', 'm.pdb']))"
    )
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "particles" in lines[0], done.stderr
