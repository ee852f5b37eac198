"""Staging a particle frame without per-particle strings or float64 copies: labels as codes
into a name table (against NumPy's own ``np.unique``), the up-axis turn (against NumPy's
float64 matrix product), sphere bounds in slices (against the whole float64 sums), and a
GSD frame's scene against the reader library's own values."""

from __future__ import annotations

import itertools

import gsd.hoomd
import numpy as np
import pytest

from embree_rt.scene.model import Scene
from embree_rt.scene.particles import ParticleFileError, read_particles
from embree_rt.scene.particles.frame import coded, coded_table, gathered
from embree_rt.scene.particles.look import ParticleLook, label_look, particle_look
from embree_rt.scene.particles.to_scene import UP_ROTATIONS, turned_up
from embree_rt.scene.staging import sphere_bounds


def test_coded_table_is_np_unique_of_the_strings() -> None:
    """A file's table may be unsorted, repeat a name and hold names no particle uses: the
    codes still say what ``np.unique`` of the (n,) strings says (its names and inverse)."""
    names = np.array(["Z", "B", "A", "B", "unused", "10", "2"])
    rng = np.random.default_rng(3)
    codes = rng.choice([0, 1, 2, 3, 5, 6], 1000).astype(np.uint32)
    labelled = coded_table(names, codes)
    expected_names, expected_codes, expected_counts = np.unique(
        names[codes], return_inverse=True, return_counts=True
    )
    np.testing.assert_array_equal(labelled.names, expected_names)
    np.testing.assert_array_equal(labelled.codes, expected_codes)
    np.testing.assert_array_equal(labelled.counts(), expected_counts)
    assert labelled.codes.dtype == np.uint8  # one byte a particle for a few names
    np.testing.assert_array_equal(labelled.values(), names[codes])
    np.testing.assert_array_equal(coded(names[codes]).codes, expected_codes)


def test_gathered_is_fancy_indexing_across_slices(monkeypatch) -> None:
    from embree_rt.scene.particles import frame as frame_module

    monkeypatch.setattr(frame_module, "GATHER_ROWS", 7)  # many slices, and a short last one
    table = np.arange(15, dtype=np.float64).reshape(5, 3)
    codes = np.random.default_rng(4).integers(0, 5, 100).astype(np.uint8)
    np.testing.assert_array_equal(gathered(table, codes), table[codes])


@pytest.mark.parametrize("up", ["x", "y", "z"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_turned_up_is_the_float64_product_bit_for_bit(up: str, dtype) -> None:
    """Every sign of zero beside numbers of both signs: the turn equals NumPy's float64
    product (cast to the positions' dtype) in its bits, the zeros' signs included. Bitwise on
    every ISA: each coordinate is one product by +-1 plus products by 0, all exact."""
    values = [0.0, -0.0, 1.5, -2.5, 3e-39, -7e7]
    positions = np.array(list(itertools.product(values, repeat=3)), dtype)
    expected = (positions.astype(np.float64) @ UP_ROTATIONS[up].T + 0.0).astype(dtype)
    turned = turned_up(positions, up)
    assert turned.dtype == dtype
    np.testing.assert_array_equal(turned.view(np.uint8), expected.view(np.uint8))
    assert not np.signbit(turned[turned == 0]).any()


def test_sphere_bounds_in_slices_are_the_whole_sums(monkeypatch) -> None:
    from embree_rt.scene import staging

    monkeypatch.setattr(staging, "BOUNDS_ROWS", 5)
    rng = np.random.default_rng(5)
    centers = rng.normal(size=(101, 3)).astype(np.float32) * 100
    radii = rng.uniform(0.1, 3.0, 101).astype(np.float32)
    low, high = sphere_bounds(centers, radii)
    wide_centers, wide_radii = centers.astype(np.float64), radii.astype(np.float64)[:, None]
    np.testing.assert_array_equal(low, (wide_centers - wide_radii).min(axis=0))
    np.testing.assert_array_equal(high, (wide_centers + wide_radii).max(axis=0))


def write_gsd(path, names, typeid, positions, **particles) -> None:
    frame = gsd.hoomd.Frame()
    frame.particles.N = len(positions)
    frame.particles.types = names
    frame.particles.typeid = typeid
    frame.particles.position = positions
    for name, values in particles.items():
        setattr(frame.particles, name, values)
    frame.configuration.box = [20, 20, 20, 0, 0, 0]
    with gsd.hoomd.open(str(path), "w") as trajectory:
        trajectory.append(frame)


def test_gsd_scene_holds_the_readers_values(tmp_path) -> None:
    """The spheres of a GSD frame: centres the file's float32 positions turned z up, colours
    and radii by type as ``label_look`` gives them for the (n,) type strings."""
    rng = np.random.default_rng(6)
    names = ["B", "A", "unused", "C"]
    typeid = rng.choice([0, 1, 3], 500).astype(np.uint32)
    positions = rng.normal(size=(500, 3)).astype(np.float32) * 5
    path = tmp_path / "mixed.gsd"
    write_gsd(path, names, typeid, positions)
    with gsd.hoomd.open(str(path), "r") as trajectory:
        stored = trajectory[0].particles
        strings = np.array(stored.types)[stored.typeid]
        expected_positions = stored.position
    frame = read_particles(path)
    assert frame.positions.dtype == np.float32  # as gsd gives them
    np.testing.assert_array_equal(frame.positions, expected_positions)
    np.testing.assert_array_equal(frame.types, strings)
    look = ParticleLook(radius_scale=0.3)
    colors, radii = particle_look(frame, look)
    table_colors, table_radii = label_look(str(path), "type", strings)
    np.testing.assert_array_equal(radii, table_radii * 0.3)
    np.testing.assert_array_equal(
        colors, np.clip(np.rint(table_colors * 255.0), 0, 255).astype(np.uint8)
    )
    scene = Scene.from_particles(path, look=look, floor=False)
    assert scene.sphere_centers.flags.c_contiguous  # as Embree's buffers read it, uncopied
    turned = np.stack(
        [expected_positions[:, 0], expected_positions[:, 2], -expected_positions[:, 1]]
    )
    np.testing.assert_array_equal(scene.sphere_centers, turned.T + np.float32(0.0))
    np.testing.assert_array_equal(scene.sphere_radii, (table_radii * 0.3).astype(np.float32))


def test_gsd_typeid_past_its_names_is_refused(tmp_path) -> None:
    path = tmp_path / "bad.gsd"
    write_gsd(path, ["A", "B"], np.array([0, 1, 2], np.uint32), np.zeros((3, 3), np.float32))
    with pytest.raises(ParticleFileError, match=r"bad\.gsd: frame 0: particles/typeid 2 is past"):
        read_particles(path)


def test_type_palette_is_matplotlibs_tab10() -> None:
    """Types are coloured by matplotlib's tab10, in the types' natural order, the eleventh
    taking the first colour again: matplotlib's own floats, bit for bit."""
    import matplotlib

    from embree_rt.scene.particles.look import TYPE_PALETTE, label_table

    names = np.array([str(i) for i in range(1, 12)])  # natural order: 1, 2, ..., 10, 11
    colors, _ = label_table("x", "type", np.sort(names))
    tab10 = np.asarray(matplotlib.colormaps[TYPE_PALETTE].colors, np.float64)[:, :3]
    by_name = dict(zip(np.sort(names).tolist(), colors, strict=True))
    expected = tab10[np.arange(11) % 10]
    np.testing.assert_array_equal(np.array([by_name[n] for n in names]), expected)


@pytest.mark.parametrize("follow", [False, True])
def test_trajectory_frames_are_the_stills_of_their_frames(tmp_path, follow: bool) -> None:
    """Frame k of a GSD trajectory is the still ``Scene.from_particles(path, frame=k)`` renders,
    seen by the first frame's camera, lights and floor (by its own with ``--follow``): frames
    after the first are not framed, yet look as a framed frame would."""
    import embree_rt as rt
    from embree_rt.cli import main

    rng = np.random.default_rng(8)
    start = rng.uniform(-3.0, 3.0, (60, 3)).astype(np.float32)
    path = tmp_path / "t.gsd"
    with gsd.hoomd.open(str(path), "w") as trajectory:
        for k in range(3):
            frame = gsd.hoomd.Frame()
            frame.particles.N = len(start)
            frame.particles.types = ["A", "B"]
            frame.particles.typeid = (np.arange(len(start)) % 2).astype(np.uint32)
            frame.particles.position = start * (1.0 + 0.3 * k)  # (the bounds grow)
            frame.configuration.box = [20, 20, 20, 0, 0, 0]
            trajectory.append(frame)
    size = ["--width", "32", "--height", "24", "--spp", "1", "--threads", "2", "--quiet"]
    flags = ["--follow"] if follow else []
    out = tmp_path / "f_{frame}.npy"
    assert main(["render", str(path), "-o", str(out), *size, *flags]) in (0, None)
    first = Scene.from_particles(path, frame=0)
    images = []
    for k in range(3):
        still = Scene.from_particles(path, frame=k)
        if not follow:
            still.camera, still.lights, still.floor = first.camera, first.lights, first.floor
        expected = rt.render(still, width=32, height=24, spp=1, threads=2).image
        images.append(np.load(tmp_path / f"f_{k}.npy"))
        np.testing.assert_array_equal(images[-1], expected)
    assert not np.array_equal(images[0], images[2])
