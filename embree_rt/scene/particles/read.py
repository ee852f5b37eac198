"""Reading one frame of a particle file through the library that reads its format best.

Which library reads what (chosen by coverage and speed, see ``docs/particles.md``):
MDAnalysis reads the molecular formats with topologies (PDB, PQR, GRO, Mol2, LAMMPS data, and
DCD/XTC/TRR trajectories over a topology such as PSF, and PDBx/mmCIF through gemmi), naming
elements, types, PQR's radii and the box; ASE reads the materials formats (XYZ and extended
XYZ, VASP POSCAR/CONTCAR, CIF) with their per-atom arrays; ``gsd`` reads HOOMD's GSD; LAMMPS
text dumps are read by a parallel parser of their own (``lammps_dump``). A ``.gz``, ``.bz2`` or
``.xz`` copy is decompressed to a temporary file and read as the file it holds.
"""

from __future__ import annotations

import bz2
import gzip
import itertools
import lzma
import re
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from embree_rt.errors import InputError, install_hint
from embree_rt.scene.particles.errors import ParticleFileError, check_count
from embree_rt.scene.particles.frame import ParticleFrame, coded_table

COMPRESSED = {".gz": gzip.open, ".bz2": bz2.open, ".xz": lzma.open}
ASE_FORMATS = {
    ".xyz": "extxyz",
    ".extxyz": "extxyz",
    ".poscar": "vasp",
    ".vasp": "vasp",
    ".cif": "cif",
}
ASE_NAMES = {"POSCAR": "vasp", "CONTCAR": "vasp"}
MDA_FORMATS = {
    ".pdb": "PDB",
    ".ent": "PDB",
    ".pqr": "PQR",
    ".gro": "GRO",
    ".mol2": "MOL2",
    ".data": "DATA",
    ".lmp": "DATA",
    ".psf": "PSF",
}
# A ``.cif`` holding an ``_atom_site.Cartn_x`` column is PDBx/mmCIF (macromolecules, read by
# MDAnalysis through gemmi); any other ``.cif`` is a crystallographic CIF (read by ASE).
MMCIF_SUFFIXES = (".mmcif", ".mcif")
MMCIF_MARK = re.compile(rb"^_atom_site\.cartn_x\b", re.IGNORECASE | re.MULTILINE)
TRAJECTORY_SUFFIXES = (".dcd", ".xtc", ".trr")
DUMP_SUFFIXES = (".lammpstrj", ".dump")
GSD_SUFFIXES = (".gsd",)
PARTICLE_SUFFIXES = (
    *ASE_FORMATS,
    *MMCIF_SUFFIXES,
    *MDA_FORMATS,
    *TRAJECTORY_SUFFIXES,
    *DUMP_SUFFIXES,
    *GSD_SUFFIXES,
)


def inner_name(path: str | Path) -> str:
    """The file name without a compression suffix (``a.pdb.gz`` -> ``a.pdb``)."""
    name = Path(path).name
    suffix = Path(name).suffix.lower()
    return name[: -len(suffix)] if suffix in COMPRESSED else name


def is_particle_file(path: str | Path) -> bool:
    """Whether ``path`` names a particle file, by its extension (a compressed one's inner)."""
    name = inner_name(path)
    return Path(name).suffix.lower() in PARTICLE_SUFFIXES or name in ASE_NAMES


def read_particles(
    path: str | Path, frame: int = 0, topology: str | Path | None = None
) -> ParticleFrame:
    """Frame ``frame`` of the particle file ``path`` (a trajectory over ``topology``), checked:
    at least one particle, finite positions, positive radii. Raises ``ParticleFileError``
    (``InputError`` when the ``particles`` extra is missing)."""
    path = Path(path)
    if not path.is_file():
        raise ParticleFileError(path, "(file)", "no such file")
    with _plain_copy(path) as plain:
        if topology is not None:
            topology = Path(topology)
            if not topology.is_file():
                raise ParticleFileError(topology, "(file)", "no such topology file")
        with _plain_copy(topology) if topology is not None else _nothing() as topo:
            result = _read(path, plain, frame, topo)
    result.path = str(path)
    _check(result)
    return result


@contextmanager
def _nothing() -> Iterator[None]:
    yield None


@contextmanager
def _plain_copy(path: Path) -> Iterator[Path]:
    """``path`` itself, or its decompressed content in a temporary file of the inner name."""
    opener = COMPRESSED.get(path.suffix.lower())
    if opener is None:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="embree_rt_particles_") as folder:
        plain = Path(folder) / inner_name(path)
        try:
            with opener(path, "rb") as source, open(plain, "wb") as target:
                shutil.copyfileobj(source, target, 1 << 22)
        except (OSError, EOFError, lzma.LZMAError) as error:
            raise ParticleFileError(path, "(file)", f"cannot decompress: {error}") from None
        yield plain


def _read(path: Path, plain: Path, frame: int, topology: Path | None) -> ParticleFrame:
    name = plain.name
    suffix = plain.suffix.lower()
    if plain.stat().st_size == 0:
        raise ParticleFileError(path, "(file)", "the file is empty")
    if suffix in DUMP_SUFFIXES:
        return _read_dump(path, plain, frame)
    if suffix in GSD_SUFFIXES:
        return _read_gsd(path, plain, frame)
    if suffix in MMCIF_SUFFIXES or (suffix == ".cif" and is_mmcif(plain)):
        _require("gemmi")  # MDAnalysis's mmCIF reader stands on it
        return _read_mdanalysis(path, plain, frame, None, file_format="MMCIF")
    if suffix in ASE_FORMATS or name in ASE_NAMES:
        return _read_ase(path, plain, ASE_FORMATS.get(suffix) or ASE_NAMES[name], frame)
    if suffix in TRAJECTORY_SUFFIXES and topology is None:
        raise ParticleFileError(
            path, "(file)", f"a {suffix} trajectory holds no atoms' names: give --topology FILE"
        )
    return _read_mdanalysis(path, plain, frame, topology)


def is_mmcif(plain: Path) -> bool:
    """Whether the CIF ``plain`` is PDBx/mmCIF: its atoms in an ``_atom_site.Cartn_x``
    column (a crystallographic CIF names ``_atom_site_fract_x``)."""
    return MMCIF_MARK.search(plain.read_bytes()) is not None


def _require(module: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(
            f"reading particle files needs {module}: "
            + install_hint("particles", "ase MDAnalysis gsd matplotlib gemmi")
        ) from None


def _frame_problem(path: Path, frame: int, count: int) -> None:
    if not 0 <= frame < count:
        raise ParticleFileError(
            path, f"frame {frame}", f"past the end: the file holds {count} frame(s), 0..{count - 1}"
        )


def _read_dump(path: Path, plain: Path, frame: int) -> ParticleFrame:
    from embree_rt.scene.particles.lammps_dump import frame_offsets, map_file, read_dump_frame

    data = map_file(plain)
    offsets = frame_offsets(data)
    if not offsets:
        raise ParticleFileError(path, "(file)", "no 'ITEM: TIMESTEP' line: not a LAMMPS dump")
    _frame_problem(path, frame, len(offsets))
    return read_dump_frame(str(path), data, offsets, frame)


def _read_gsd(path: Path, plain: Path, frame: int) -> ParticleFrame:
    """A GSD frame read chunk by chunk (gsd's file layer): only what the file stores, its
    count checked before any array of that size is read. A chunk a frame lacks is frame 0's,
    else HOOMD's default, as ``gsd.hoomd`` does; ``gsd.hoomd``'s own frames would hold every
    attribute at its default (~290 bytes a particle), which a 1e8-particle file cannot afford."""
    layer = _require("gsd.fl")
    try:
        trajectory = layer.open(str(plain), "r")
    except Exception as error:  # gsd raises RuntimeError or OSError on a damaged file
        raise ParticleFileError(path, "(file)", f"not a readable GSD file: {error}") from None
    with trajectory:
        frame_count = int(trajectory.nframes)
        _frame_problem(path, frame, frame_count)

        def chunk(name: str) -> np.ndarray | None:
            for where in (frame, 0):
                if trajectory.chunk_exists(frame=where, name=name):
                    return trajectory.read_chunk(frame=where, name=name)
            return None

        stored_count = chunk("particles/N")
        count = int(stored_count[0]) if stored_count is not None else 0
        check_count(str(path), f"frame {frame}", count)
        position = chunk("particles/position")
        positions = (
            np.zeros((count, 3), np.float32) if position is None else np.asarray(position)
        ).reshape(-1, 3)
        stored_types = chunk("particles/types")
        names = (
            np.array(["A"])
            if stored_types is None
            else np.array([bytes(row).rstrip(b"\0").decode() for row in stored_types], dtype=str)
        )
        typeid = chunk("particles/typeid")
        typeid = np.zeros(count, np.uint8) if typeid is None else np.asarray(typeid).reshape(-1)
        if len(typeid) and int(typeid.max()) >= len(names):
            raise ParticleFileError(
                path,
                f"frame {frame}",
                f"particles/typeid {int(typeid.max())} is past the {len(names)} type name(s)",
            )
        stored_box = chunk("configuration/box")
        box_numbers = (
            np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
            if stored_box is None
            else np.asarray(stored_box, np.float64)
        )
        lx, ly, lz, xy, xz, yz = box_numbers
        box = np.array([[lx, 0, 0], [xy * ly, ly, 0], [xz * lz, yz * lz, lz]])
        result = ParticleFrame(
            path=str(path),
            positions=positions,
            type_labels=coded_table(names, typeid),
            box=box,
            origin=-box.sum(axis=0) / 2.0,
            frame=frame,
            frame_count=frame_count,
        )
        diameter = chunk("particles/diameter")
        if diameter is not None and np.any(diameter != 1.0):
            result.radii = np.asarray(diameter, np.float64) / 2.0
        bond_count = chunk("bonds/N")
        if bond_count is not None and int(bond_count[0]):
            result.bonds = np.asarray(chunk("bonds/group"), np.int64).reshape(-1, 2)
        for name in ("charge", "mass"):
            values = chunk(f"particles/{name}")
            if values is not None:
                result.properties[name] = np.asarray(values, np.float64)
        velocity = chunk("particles/velocity")
        if velocity is not None:
            columns = np.asarray(velocity, np.float64).reshape(-1, 3).T
            for axis, values in zip("xyz", columns, strict=True):
                result.properties[f"v{axis}"] = values
        return result


def _xyz_headers(path: Path, plain: Path) -> None:
    """Refuse an XYZ frame header whose count would not fit in memory, before ASE reads it."""
    with open(plain, "rb") as handle:
        first = handle.readline().split()
    if first and first[0].isdigit():
        check_count(str(path), "frame 0", int(first[0]))


def _read_ase(path: Path, plain: Path, file_format: str, frame: int) -> ParticleFrame:
    ase_io = _require("ase.io")
    if file_format == "extxyz":
        _xyz_headers(path, plain)
    try:
        frames = ase_io.read(str(plain), index=":", format=file_format)
    except KeyError:
        if file_format != "extxyz":
            raise
        # A symbol ASE does not know: MDAnalysis's XYZ reader keeps it as a name, drawn in the
        # unknown element's colour (with a warning) rather than refused.
        result = _read_mdanalysis(path, plain, frame, None, file_format="XYZ")
        result.elements = np.asarray(result.source.atoms.names, dtype=str)
        return result
    except Exception as error:  # ASE's readers raise whatever their parsing meets
        raise ParticleFileError(path, "(file)", _one_line(error)) from None
    if not frames:
        raise ParticleFileError(path, "(file)", "no frames")
    _frame_problem(path, frame, len(frames))
    atoms = frames[frame]
    result = ParticleFrame(
        path=str(path),
        positions=np.asarray(atoms.get_positions(), np.float64),
        frame=frame,
        frame_count=len(frames),
    )
    result.elements = atoms.get_chemical_symbols()
    cell = np.asarray(atoms.cell[:], np.float64)
    if np.any(cell):
        result.box = cell
    for name, values in atoms.arrays.items():
        if name in ("numbers", "positions"):
            continue
        values = np.asarray(values)
        if values.dtype.kind not in "fiub":
            continue
        if values.ndim == 1:
            result.properties[name] = values.astype(np.float64)
        elif values.ndim == 2 and values.shape[1] == 3:
            for axis, column in zip("xyz", values.T, strict=True):
                result.properties[f"{name}_{axis}"] = column.astype(np.float64)
    if "radius" in result.properties:
        result.radii = result.properties.pop("radius")
    return result


def _read_mdanalysis(
    path: Path, plain: Path, frame: int, topology: Path | None, file_format: str | None = None
) -> ParticleFrame:
    mda = _require("MDAnalysis")
    import warnings

    file_format = file_format or MDA_FORMATS.get(plain.suffix.lower())

    claimed = None if topology is not None else header_count(plain, file_format)
    if claimed is not None:
        check_count(str(path), "(header)", claimed)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its guesses of missing attributes, said per file
            if topology is not None:
                universe = mda.Universe(str(topology))
                _check_trajectory_count(path, plain, topology, len(universe.atoms))
                universe.load_new(str(plain))
            else:
                options = {}
                if file_format == "DATA":
                    options["atom_style"] = data_atom_style(path, plain)
                universe = mda.Universe(str(plain), format=file_format, **options)
    except ParticleFileError:
        raise
    except Exception as error:  # MDAnalysis's parsers raise ValueError, OSError, EOFError...
        raise ParticleFileError(path, "(file)", _one_line(error)) from None
    if claimed is not None and claimed != len(universe.atoms):
        raise ParticleFileError(
            path,
            "(header)",
            f"claims {claimed:,} particles but the file holds {len(universe.atoms):,} "
            "(a truncated file?)",
        )
    count = len(universe.trajectory)
    _frame_problem(path, frame, count)
    try:
        universe.trajectory[frame]
    except Exception as error:
        raise ParticleFileError(path, f"frame {frame}", _one_line(error)) from None
    atoms = universe.atoms
    result = ParticleFrame(
        path=str(path),
        positions=np.asarray(atoms.positions),
        frame=frame,
        frame_count=count,
    )
    if hasattr(atoms, "types"):
        result.types = np.asarray(atoms.types, dtype=str)
    elements = _mda_elements(universe)
    if elements is not None:
        result.elements = elements
    if hasattr(atoms, "radii"):
        result.radii = np.asarray(atoms.radii, np.float64)
    for name, key in MDA_PROPERTIES.items():
        if hasattr(atoms, name):
            result.properties[key] = np.asarray(getattr(atoms, name), np.float64)
    if topology is None and MDA_FORMATS.get(plain.suffix.lower()) == "DATA":
        diameters = sphere_diameters(plain, atoms.ids)
        if diameters is not None:
            result.radii = diameters / 2.0
    if universe.dimensions is not None and np.all(universe.dimensions[:3] > 0):
        from MDAnalysis.lib.mdamath import triclinic_vectors

        result.box = np.asarray(triclinic_vectors(universe.dimensions), np.float64)
    if hasattr(atoms, "bonds") and len(atoms.bonds):
        result.bonds = np.asarray(atoms.bonds.indices, np.int64).reshape(-1, 2)
    result.source = universe
    return result


def _check_trajectory_count(path: Path, plain: Path, topology: Path, atoms: int) -> None:
    """Refuse a trajectory whose frames hold another number of atoms than its topology's
    ``atoms`` (read from the trajectory's header by MDAnalysis's own reader)."""
    from MDAnalysis.coordinates.core import reader

    with reader(str(plain)) as frames:
        count = frames.n_atoms
    if count != atoms:
        raise ParticleFileError(
            path,
            "(file)",
            f"its frames hold {count:,} atoms but the topology {topology.name} has {atoms:,}",
        )


def header_count(plain: Path, file_format: str | None) -> int | None:
    """The particle count the header of a GRO (its second line), LAMMPS data (``N atoms``)
    or Mol2 (the line after ``@<TRIPOS>MOLECULE``'s name) file claims; None for another
    format or a header that states none. Read before MDAnalysis, which allocates by it."""
    if file_format not in ("GRO", "DATA", "MOL2"):
        return None
    with open(plain, "rb") as handle:
        head = [line.partition(b"#")[0].split() for line in itertools.islice(handle, 200)]
    if file_format == "GRO":
        words = head[1] if len(head) > 1 else []
    elif file_format == "DATA":
        words = next((w for w in head if len(w) == 2 and w[1] == b"atoms"), [])
    else:
        at = next((i for i, w in enumerate(head) if w[:1] == [b"@<TRIPOS>MOLECULE"]), None)
        words = head[at + 2] if at is not None and at + 2 < len(head) else []
    return int(words[0]) if words and words[0].isdigit() else None


# MDAnalysis's per-atom attributes kept as properties, by the names they take.
MDA_PROPERTIES = {
    "charges": "charge",
    "masses": "mass",
    "tempfactors": "tempfactor",
    "occupancies": "occupancy",
    "resids": "resid",
}
# LAMMPS data files' atom styles as MDAnalysis's ``atom_style`` (the columns before image flags)
DATA_STYLES = {
    "atomic": "id type x y z",
    "charge": "id type charge x y z",
    "molecular": "id resid type x y z",
    "bond": "id resid type x y z",
    "angle": "id resid type x y z",
    "full": "id resid type charge x y z",
    "sphere": "id type diameter density x y z",
}
# Without an ``Atoms # style`` comment, by the count of columns (image flags add 3).
DATA_STYLE_BY_COLUMNS = {5: "atomic", 6: "molecular", 7: "full"}


def data_atom_style(path: Path, plain: Path) -> str:
    """MDAnalysis's ``atom_style`` of a LAMMPS data file: from its ``Atoms # style`` comment,
    else from the number of columns of its first atom line."""
    lines = iter(plain.read_text(errors="replace").splitlines())
    for line in lines:
        words = line.split()
        if words[:1] != ["Atoms"]:
            continue
        comment = line.partition("#")[2].split()
        if comment:
            if comment[0] not in DATA_STYLES:
                raise ParticleFileError(
                    path,
                    "Atoms",
                    f"atom style {comment[0]!r} is not one of {', '.join(DATA_STYLES)}",
                )
            return DATA_STYLES[comment[0]]
        for row in lines:
            columns = len(row.partition("#")[0].split())
            if columns:
                style = DATA_STYLE_BY_COLUMNS.get(columns) or DATA_STYLE_BY_COLUMNS.get(columns - 3)
                if style is None:
                    raise ParticleFileError(
                        path, "Atoms", f"{columns} columns match no atom style; add '# STYLE'"
                    )
                return DATA_STYLES[style]
    raise ParticleFileError(path, "Atoms", "no Atoms section")


def sphere_diameters(plain: Path, ids: np.ndarray) -> np.ndarray | None:
    """(n,) float64 diameters of the atoms ``ids`` (n,) of a LAMMPS data file of atom style
    ``sphere`` (its third column; MDAnalysis keeps no diameter), None for another style."""
    lines = plain.read_text(errors="replace").splitlines()
    start = next((i for i, line in enumerate(lines) if line.split()[:1] == ["Atoms"]), None)
    if start is None or lines[start].partition("#")[2].split()[:1] != ["sphere"]:
        return None
    rows = []
    for line in lines[start + 1 :]:
        words = line.partition("#")[0].split()
        if not words:
            if rows:
                break
            continue
        if not words[0].lstrip("-").isdigit():
            break
        rows.append((int(words[0]), float(words[2])))
    by_id = dict(rows)
    return np.array([by_id[int(i)] for i in ids], np.float64)


def _mda_elements(universe) -> np.ndarray | None:
    """Elements as the file names them, else as MDAnalysis guesses them from atom names and
    types (GRO, PSF), else None when it cannot."""
    atoms = universe.atoms
    if hasattr(atoms, "elements"):
        elements = np.asarray(atoms.elements, dtype=str)
        if np.all(elements != ""):
            return np.char.capitalize(elements)
    if not hasattr(atoms, "names"):
        return None
    from MDAnalysis.guesser.default_guesser import DefaultGuesser
    from MDAnalysis.guesser.tables import masses

    guessed = np.asarray(DefaultGuesser(universe).guess_types(atoms.names), dtype=str)
    known = np.isin(np.char.upper(guessed), [name.upper() for name in masses])
    return np.char.capitalize(guessed) if known.mean() > 0.5 else None


def _check(frame: ParticleFrame) -> None:
    where = f"frame {frame.frame}"
    if len(frame) == 0:
        raise ParticleFileError(frame.path, where, "no particles")
    # (NaN and infinities reach the minimum or maximum: no (n, 3) mask unless one is there)
    finite = np.isfinite(frame.positions.min()) and np.isfinite(frame.positions.max())
    bad = None if finite else ~np.isfinite(frame.positions).all(axis=1)
    if bad is not None:
        row = int(np.argmax(bad))
        raise ParticleFileError(
            frame.path,
            where,
            f"particle {row}: position {frame.positions[row].tolist()} is not finite",
        )
    if frame.radii is not None:
        bad = ~(frame.radii > 0) | ~np.isfinite(frame.radii)
        if bad.any():
            row = int(np.argmax(bad))
            raise ParticleFileError(
                frame.path, where, f"particle {row}: radius {frame.radii[row]:g} is not positive"
            )


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return text[:300]
