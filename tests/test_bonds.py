"""Bonds of particle files drawn as sticks: the bonds a file lists, as its reader library's own
writer put them there; bonds guessed by VMD's distance rule, against a float64 brute force;
each half-stick a capsule of the stick radius in its atom's colour; bad bonds one line, exit 2."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import gsd.hoomd
import MDAnalysis
import numpy as np
import pytest
from MDAnalysis.guesser.tables import vdwradii
from tolerances import position_atol

from embree_rt.geometry import SceneGeometry
from embree_rt.scene.model import Scene
from embree_rt.scene.particles import read_particles
from embree_rt.scene.particles.bonds import BondLook
from embree_rt.scene.particles.look import ParticleLook
from embree_rt.textures import SRGB8_TO_LINEAR

ROOT = Path(__file__).resolve().parents[1]
# A chain zig-zagging in the xy-plane, bonds 1.6 long: far enough apart that small atoms leave
# each stick's middle in the open.
CHAIN = np.array([[0.0, 0.0, 0.0], [1.6, 0.0, 0.0], [2.4, 1.3856, 0.0], [4.0, 1.3856, 0.0]])
ELEMENTS = ["C", "O", "N", "C"]
CHAIN_BONDS = [(0, 1), (1, 2), (2, 3)]


def pairs(bonds) -> set[tuple[int, int]]:
    return {tuple(sorted(map(int, pair))) for pair in np.asarray(bonds).reshape(-1, 2)}


def write_pdb(path: Path) -> None:
    """The chain as a PDB with CONECT records, written by MDAnalysis."""
    universe = MDAnalysis.Universe.empty(len(CHAIN), trajectory=True)
    universe.atoms.positions = CHAIN
    universe.add_TopologyAttr("names", ELEMENTS)
    universe.add_TopologyAttr("elements", ELEMENTS)
    universe.add_TopologyAttr("resnames", ["MOL"])
    universe.add_TopologyAttr("bonds", CHAIN_BONDS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        universe.atoms.write(str(path))


def write_gsd(path: Path, bonds: list[tuple[int, int]]) -> None:
    """The chain as a GSD frame with ``bonds``, written by gsd."""
    frame = gsd.hoomd.Frame()
    frame.particles.N = len(CHAIN)
    frame.particles.position = CHAIN.astype(np.float32)
    frame.particles.types = ["A"]
    frame.particles.typeid = np.zeros(len(CHAIN), np.uint32)
    frame.configuration.box = [20.0, 20.0, 20.0, 0.0, 0.0, 0.0]
    frame.bonds.N = len(bonds)
    frame.bonds.types = ["backbone"]
    frame.bonds.typeid = np.zeros(len(bonds), np.uint32)
    frame.bonds.group = np.array(bonds, np.uint32).reshape(-1, 2)
    with gsd.hoomd.open(str(path), "w") as trajectory:
        trajectory.append(frame)


def test_bonds_of_a_pdb_with_conect_are_mdanalysis_own(tmp_path):
    write_pdb(tmp_path / "chain.pdb")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = MDAnalysis.Universe(str(tmp_path / "chain.pdb")).atoms.bonds.indices
    frame = read_particles(tmp_path / "chain.pdb")
    assert pairs(frame.bonds) == pairs(own) == set(CHAIN_BONDS)
    scene = Scene.from_particles(tmp_path / "chain.pdb", bonds=BondLook(), floor=False)
    assert sum(len(curves) for curves in scene.curves) == 2 * len(CHAIN_BONDS)
    assert any("listed in the file" in note for note in scene.notes)


def test_bonds_of_a_gsd_are_gsd_own_and_kept_through_a_selection(tmp_path):
    write_gsd(tmp_path / "chain.gsd", CHAIN_BONDS)
    with gsd.hoomd.open(str(tmp_path / "chain.gsd"), "r") as trajectory:
        own = trajectory[0].bonds.group
    frame = read_particles(tmp_path / "chain.gsd")
    assert pairs(frame.bonds) == pairs(own) == set(CHAIN_BONDS)
    # particles 1..3 kept: the bonds among them, renumbered from 0
    assert pairs(frame.subset(np.array([1, 2, 3])).bonds) == {(0, 1), (1, 2)}


def test_guessed_bonds_follow_vdw_radii_by_float64_brute_force(tmp_path):
    rng = np.random.default_rng(5)
    positions = rng.uniform(0.0, 6.0, size=(60, 3))
    elements = rng.choice(["C", "H", "O", "N"], size=60)
    lines = [str(len(positions)), ""]
    rows = zip(elements, positions, strict=True)
    lines += [f"{e} {x:.6f} {y:.6f} {z:.6f}" for e, (x, y, z) in rows]
    (tmp_path / "cloud.xyz").write_text("\n".join(lines) + "\n")
    frame = read_particles(tmp_path / "cloud.xyz")
    from embree_rt.scene.particles.bonds import frame_bonds

    radius = np.array([vdwradii[e.upper()] for e in elements])
    distance = np.linalg.norm(frame.positions[:, None] - frame.positions[None], axis=2)
    limit = 0.55 * (radius[:, None] + radius[None, :])
    i, j = np.nonzero(np.triu((distance < limit) & (distance > 0.1), 1))
    # pairs within float32 rounding of the limit are decided either way
    near = np.abs(distance - limit) < 1e-5
    assert not near[i, j].any()
    expected = set(zip(i.tolist(), j.tolist(), strict=True))
    assert len(expected) > 10 and pairs(frame_bonds(frame)) == expected


def test_a_ray_at_a_half_bond_meets_its_capsule_in_its_atoms_colour(tmp_path):
    write_pdb(tmp_path / "chain.pdb")
    radius = 0.2
    look = ParticleLook(radius=0.3)
    scene = Scene.from_particles(
        tmp_path / "chain.pdb", look=look, bonds=BondLook(radius=radius), floor=False, up="y"
    )
    ends = scene.sphere_centers.astype(np.float64)
    origins, directions, expected_t, atoms = [], [], [], []
    for a, b in CHAIN_BONDS:
        axis = ends[b] - ends[a]
        side = np.cross(axis, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        for share, atom in ((0.35, a), (0.65, b)):  # a point on each half, clear of the balls
            target = ends[a] + share * axis
            origins.append(target + 7.0 * side)
            directions.append(-side)
            expected_t.append(7.0 - radius)  # float64: the capsule's surface along the ray
            atoms.append(atom)
    o = np.ascontiguousarray(np.array(origins).T, np.float32)
    d = np.ascontiguousarray(np.array(directions).T, np.float32)
    with SceneGeometry(scene) as geometry:
        hits = geometry.intersect(o, d)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.t, expected_t, rtol=0, atol=position_atol(o, 10.0))
    names = list(scene.materials)
    colors = np.array([scene.materials[names[m]].color for m in hits.material])
    expected = SRGB8_TO_LINEAR[scene.sphere_colors[atoms]]
    np.testing.assert_array_equal(colors.astype(np.float32), expected)


def test_licorice_draws_atoms_at_the_sticks_radius(tmp_path):
    write_pdb(tmp_path / "chain.pdb")
    scene = Scene.from_particles(
        tmp_path / "chain.pdb", bonds=BondLook(radius=0.25, licorice=True), floor=False
    )
    assert np.all(scene.sphere_radii == np.float32(0.25))
    assert all(np.all(curves.radii == np.float32(0.25)) for curves in scene.curves)


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args], cwd=cwd, env=env, capture_output=True, text=True
    )


@pytest.mark.parametrize(
    "case",
    ["out_of_range", "no_elements", "radius_without_bonds"],
)
def test_bad_bonds_one_line_exit_2_nothing_written(tmp_path, case):
    flags = ["--bonds"]
    if case == "out_of_range":
        write_gsd(tmp_path / "chain.gsd", [(0, 1), (2, 9)])
        problem = "bond 1 joins particles [2, 9]"
    elif case == "no_elements":  # a GSD of types, no bonds: nothing to guess them by
        write_gsd(tmp_path / "chain.gsd", [])
        problem = "names no elements"
    else:
        write_gsd(tmp_path / "chain.gsd", CHAIN_BONDS)
        flags = ["--bond-radius", "0.2"]
        problem = "needs --bonds"
    done = run(
        "render", "chain.gsd", "-o", "o.png", "--width", "16", "--height", "16", *flags,
        cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and problem in lines[0], done.stderr
    assert not (tmp_path / "o.png").exists()
