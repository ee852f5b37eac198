"""Every particle format of issue 35's list, each file made by its library's own writer (by
hand where none writes it: PSF, LAMMPS dumps), read back against that library's own reading:
counts and positions; compressed copies (.gz, .bz2, .xz) read as the plain file; PQR's radii;
PDBx/mmCIF through gemmi; DCD, XTC and TRR trajectories over a PSF topology."""

from __future__ import annotations

import bz2
import gzip
import lzma
import warnings
from pathlib import Path

import numpy as np
import pytest
from particle_samples import MOL2

ase_io = pytest.importorskip("ase.io")
import ase.build  # noqa: E402
import gemmi  # noqa: E402
import gsd.hoomd  # noqa: E402
import MDAnalysis  # noqa: E402

from embree_rt.scene.particles import read_particles  # noqa: E402

COMPRESSORS = {".gz": gzip.compress, ".bz2": bz2.compress, ".xz": lzma.compress}
WATER = np.array([[0.0, 0.0, 0.1173], [0.0, 0.7572, -0.4692], [0.0, -0.7572, -0.4692]])


def molecule() -> ase.Atoms:
    atoms = ase.build.molecule("CH3CH2OH")
    atoms.center(vacuum=3.0)
    return atoms


def universe(path: Path, *more: str, **options) -> MDAnalysis.Universe:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its guesses of attributes the file does not hold
        return MDAnalysis.Universe(str(path), *more, **options)


def write_psf(path: Path) -> None:
    """A water PSF by hand (MDAnalysis reads PSF but writes none), CHARMM's fixed columns."""
    atoms = [("OH2", "OT", -0.834, 15.9994), ("H1", "HT", 0.417, 1.008), ("H2", "HT", 0.417, 1.008)]
    lines = ["PSF", "", "       1 !NTITLE", " REMARKS a test's water", "", "       3 !NATOM"]
    for i, (name, kind, charge, mass) in enumerate(atoms):
        lines.append(
            f"{i + 1:8d} {'W':<4} {1:<4d} {'HOH':<4} {name:<4} {kind:<4} {charge:14.6f}"
            f"{mass:14.4f}{0:12d}"
        )
    path.write_text("\n".join([*lines, "", "       0 !NBOND: bonds", "", ""]))


def make_xyz(folder: Path) -> tuple[Path, np.ndarray]:
    path = folder / "m.xyz"
    ase_io.write(path, [molecule(), molecule()], format="extxyz")
    return path, ase_io.read(path, index=0).get_positions()


def make_ase(name: str, fmt: str):
    def make(folder: Path) -> tuple[Path, np.ndarray]:
        path = folder / name
        ase_io.write(path, molecule(), format=fmt)
        return path, ase_io.read(path, format=fmt).get_positions()

    return make


def make_mdanalysis(suffix: str):
    def make(folder: Path) -> tuple[Path, np.ndarray]:
        pdb = folder / "source.pdb"
        ase_io.write(pdb, molecule(), format="proteindatabank")
        path = folder / f"m{suffix}"
        source = universe(pdb)
        if suffix == ".pqr":  # radii of its own, which the PQR writer puts in its column
            count = len(source.atoms)
            source.add_TopologyAttr("charges", np.linspace(-0.5, 0.5, count))
            source.add_TopologyAttr("radii", np.linspace(1.0, 2.0, count))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # defaults for what the PDB does not hold
            source.atoms.write(str(path))
        return path, universe(path).atoms.positions

    return make


def make_mmcif(folder: Path) -> tuple[Path, np.ndarray]:
    pdb = folder / "source.pdb"
    ase_io.write(pdb, molecule(), format="proteindatabank")
    structure = gemmi.read_structure(str(pdb))
    structure.setup_entities()
    path = folder / "m.cif"
    structure.make_mmcif_document().write_file(str(path))
    read_back = gemmi.read_structure(str(path))
    gemmi_positions = [cra.atom.pos.tolist() for cra in read_back[0].all()]
    expected = universe(path, format="MMCIF").atoms.positions
    np.testing.assert_allclose(expected, gemmi_positions, atol=1e-4)  # the two readers agree
    return path, expected


def make_mol2(folder: Path) -> tuple[Path, np.ndarray]:
    by_hand = folder / "source.mol2"
    by_hand.write_text(MOL2)
    path = folder / "w.mol2"
    universe(by_hand).atoms.write(str(path))  # MDAnalysis writes MOL2 of MOL2 it read
    return path, universe(path).atoms.positions


def make_data(folder: Path) -> tuple[Path, np.ndarray]:
    water = MDAnalysis.Universe.empty(3, trajectory=True)
    water.add_TopologyAttr("types", ["1", "2", "2"])
    water.add_TopologyAttr("masses", [15.9994, 1.008, 1.008])
    for name in ("bonds", "angles", "dihedrals", "impropers"):
        water.add_TopologyAttr(name, [])
    water.atoms.positions = WATER + 2.0
    water.dimensions = [10, 10, 10, 90, 90, 90]
    path = folder / "w.data"
    water.atoms.write(str(path))
    return path, universe(path, format="DATA").atoms.positions


def make_gsd(folder: Path) -> tuple[Path, np.ndarray]:
    path = folder / "p.gsd"
    positions = np.random.default_rng(4).uniform(-3, 3, (20, 3)).astype(np.float32)
    with gsd.hoomd.open(str(path), "w") as trajectory:
        snapshot = gsd.hoomd.Frame()
        snapshot.particles.N = 20
        snapshot.particles.position = positions
        snapshot.particles.types = ["A"]
        snapshot.particles.typeid = np.zeros(20, np.uint32)
        snapshot.configuration.box = [8, 8, 8, 0, 0, 0]
        trajectory.append(snapshot)
    with gsd.hoomd.open(str(path), "r") as trajectory:
        return path, trajectory[0].particles.position


def make_dump(folder: Path) -> tuple[Path, np.ndarray]:
    """By hand (no library writes a dump); the positions as ASE's own dump reader takes them."""
    rng = np.random.default_rng(6)
    positions = np.round(rng.uniform(0, 10, (15, 3)), 5)
    rows = "".join(f"{i + 1} 1 {x} {y} {z}\n" for i, (x, y, z) in enumerate(positions))
    path = folder / "d.lammpstrj"
    path.write_text(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n15\nITEM: BOX BOUNDS pp pp pp\n"
        + "0 10\n" * 3
        + "ITEM: ATOMS id type x y z\n"
        + rows
    )
    return path, ase_io.read(path, format="lammps-dump-text", index=0).get_positions()


MAKERS = {
    "xyz": make_xyz,
    "poscar": make_ase("POSCAR", "vasp"),
    "vasp": make_ase("m.vasp", "vasp"),
    "cif": make_ase("m.cif", "cif"),
    "mmcif": make_mmcif,
    "pdb": make_mdanalysis(".pdb"),
    "pqr": make_mdanalysis(".pqr"),
    "gro": make_mdanalysis(".gro"),
    "mol2": make_mol2,
    "data": make_data,
    "gsd": make_gsd,
    "dump": make_dump,
}


@pytest.mark.parametrize("kind", sorted(MAKERS))
def test_each_format_reads_as_its_library_does(tmp_path, kind):
    path, expected = MAKERS[kind](tmp_path)
    frame = read_particles(path)
    assert len(frame) == len(expected)
    # the same numbers the library read, carried in float64 (MDAnalysis and gsd give float32)
    np.testing.assert_array_equal(frame.positions, np.asarray(expected).astype(np.float64))


@pytest.mark.parametrize("suffix", sorted(COMPRESSORS))
@pytest.mark.parametrize("kind", sorted(MAKERS))
def test_compressed_copies_read_as_the_plain_file(tmp_path, kind, suffix):
    path, _ = MAKERS[kind](tmp_path)
    packed = path.with_name(path.name + suffix)
    packed.write_bytes(COMPRESSORS[suffix](path.read_bytes()))
    plain, unpacked = read_particles(path), read_particles(packed)
    np.testing.assert_array_equal(unpacked.positions, plain.positions)
    assert unpacked.labels()[0] == plain.labels()[0]
    np.testing.assert_array_equal(unpacked.labels()[1], plain.labels()[1])
    assert unpacked.path == str(packed)


def test_pqr_radii_are_mdanalysis_radii(tmp_path):
    path, _ = make_mdanalysis(".pqr")(tmp_path)
    frame = read_particles(path)
    expected = universe(path).atoms.radii
    np.testing.assert_allclose(expected, np.linspace(1.0, 2.0, len(expected)), atol=1e-4)
    np.testing.assert_array_equal(frame.radii, expected.astype(np.float64))


def test_mmcif_elements_and_a_crystallographic_cif_stays_with_ase(tmp_path):
    path, _ = make_mmcif(tmp_path)
    assert list(read_particles(path).elements) == molecule().get_chemical_symbols()
    crystal = tmp_path / "crystal.cif"
    ase_io.write(crystal, ase.build.bulk("NaCl", "rocksalt", a=5.64), format="cif")
    frame = read_particles(crystal)
    assert sorted(frame.elements) == ["Cl", "Na"]
    np.testing.assert_allclose(frame.box, ase_io.read(crystal).cell[:], atol=1e-12)


@pytest.mark.parametrize("suffix", [".dcd", ".xtc", ".trr"])
def test_trajectory_over_a_psf_topology(tmp_path, suffix):
    psf = tmp_path / "w.psf"
    write_psf(psf)
    trajectory = tmp_path / f"w{suffix}"
    water = MDAnalysis.Universe.empty(3, trajectory=True)
    water.dimensions = [10, 10, 10, 90, 90, 90]
    with MDAnalysis.Writer(str(trajectory), 3) as writer:
        for shift in (0.0, 1.0, 2.5):
            water.atoms.positions = WATER + shift
            writer.write(water.atoms)
    expected = universe(psf, str(trajectory))
    assert len(expected.trajectory) == 3
    for number in (0, 2):
        expected.trajectory[number]
        frame = read_particles(trajectory, frame=number, topology=psf)
        assert frame.frame_count == 3 and len(frame) == 3
        np.testing.assert_array_equal(frame.positions, expected.atoms.positions.astype(np.float64))
    assert list(frame.elements) == ["O", "H", "H"]  # guessed from the PSF's names
    packed = trajectory.with_name(trajectory.name + ".gz")
    packed.write_bytes(gzip.compress(trajectory.read_bytes()))
    np.testing.assert_array_equal(
        read_particles(packed, frame=2, topology=psf).positions, frame.positions
    )
    assert list(frame.types) == ["OT", "HT", "HT"]


def test_lammps_data_styles_full_and_charge(tmp_path):
    """MDAnalysis's writer with charges writes the 7 columns of style full (no comment: the
    style detected from the count); style charge is named by hand (its 6 columns are also
    molecular's)."""
    water = MDAnalysis.Universe.empty(3, trajectory=True)
    water.add_TopologyAttr("types", ["1", "2", "2"])
    water.add_TopologyAttr("masses", [15.9994, 1.008, 1.008])
    water.add_TopologyAttr("charges", [-0.8, 0.4, 0.4])
    for name in ("bonds", "angles", "dihedrals", "impropers"):
        water.add_TopologyAttr(name, [])
    water.atoms.positions = WATER + 2.0
    water.dimensions = [10, 10, 10, 90, 90, 90]
    path = tmp_path / "full.data"
    water.atoms.write(str(path))
    expected = universe(path, format="DATA", atom_style="id resid type charge x y z").atoms
    frame = read_particles(path)
    np.testing.assert_array_equal(frame.positions, expected.positions.astype(np.float64))
    np.testing.assert_array_equal(frame.properties["charge"], expected.charges)
    charge = tmp_path / "charge.data"
    charge.write_text(
        "LAMMPS data\n\n2 atoms\n1 atom types\n\n0 10 xlo xhi\n0 10 ylo yhi\n0 10 zlo zhi\n\n"
        "Atoms # charge\n\n1 1 -0.5 1.0 2.0 3.0\n2 1 0.5 4.0 5.0 6.0\n"
    )
    frame = read_particles(charge)
    expected = universe(charge, format="DATA", atom_style="id type charge x y z").atoms
    np.testing.assert_array_equal(frame.positions, expected.positions.astype(np.float64))
    np.testing.assert_array_equal(frame.properties["charge"], [-0.5, 0.5])
