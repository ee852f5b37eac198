"""LAMMPS text dumps (``dump atom`` / ``dump custom``), read column-wise by NumPy: the frames
are found by their ``ITEM: TIMESTEP`` lines and one frame's rows parsed in one C pass
(``np.fromstring``), keeping every column (``element``, ``radius``/``diameter``, the rest as
properties). On 1e5 rows (loaded machine, ``benchmarks/particles_read.py``) ASE's reader took
0.8x its time and MDAnalysis's 2.5x: parsing the floats dominates all three."""

from __future__ import annotations

import numpy as np

from embree_rt.scene.particles.errors import ParticleFileError, check_count
from embree_rt.scene.particles.frame import ParticleFrame

TIMESTEP = b"ITEM: TIMESTEP"
# Position columns in the order they are preferred: wrapped, unwrapped, scaled (box fractions),
# scaled unwrapped.
POSITION_COLUMNS = (("x", "y", "z"), ("xu", "yu", "zu"), ("xs", "ys", "zs"), ("xsu", "ysu", "zsu"))
STRING_COLUMNS = {"element", "type"}


def frame_offsets(data: bytes) -> list[int]:
    """Byte offsets of each frame's ``ITEM: TIMESTEP`` line in a dump's ``data`` (found by
    ``bytes.find``: a multi-line regular expression took 0.3 s over 1e5 rows)."""
    offsets = []
    at = data.find(TIMESTEP)
    while at >= 0:
        if at == 0 or data[at - 1 : at] == b"\n":
            offsets.append(at)
        at = data.find(TIMESTEP, at + len(TIMESTEP))
    return offsets


def read_dump_frame(path: str, data: bytes, offsets: list[int], index: int) -> ParticleFrame:
    """Frame ``index`` of the dump whose bytes are ``data`` and frames start at ``offsets``."""
    end = offsets[index + 1] if index + 1 < len(offsets) else len(data)
    chunk = data[offsets[index] : end]
    where = f"frame {index}"
    lines = chunk.split(b"\n", 9)
    try:
        count_at = lines.index(b"ITEM: NUMBER OF ATOMS")
        count = int(lines[count_at + 1])
    except (ValueError, IndexError):
        raise ParticleFileError(
            path, where, "no 'ITEM: NUMBER OF ATOMS' line with a count"
        ) from None
    check_count(path, where, count)
    box_at = next((i for i, line in enumerate(lines) if line.startswith(b"ITEM: BOX BOUNDS")), -1)
    atoms_at = next((i for i, line in enumerate(lines) if line.startswith(b"ITEM: ATOMS")), -1)
    if box_at < 0 or atoms_at < 0:
        raise ParticleFileError(path, where, "no 'ITEM: BOX BOUNDS' or 'ITEM: ATOMS' section")
    box, origin = _box(path, where, lines[box_at : box_at + 4])
    columns = lines[atoms_at].decode("ascii", "replace").split()[2:]
    body = lines[atoms_at + 1] if atoms_at + 1 < len(lines) else b""
    table = _rows(path, where, body, columns, count)
    positions = _positions(path, where, table, box, origin)
    frame = ParticleFrame(
        path=path,
        positions=positions,
        box=box,
        origin=origin,
        frame=index,
        frame_count=len(offsets),
    )
    position_names = {name for triple in POSITION_COLUMNS for name in triple}
    for name, values in table.items():
        if name == "element":
            frame.elements = values
        elif name == "type":
            frame.types = values
        elif name == "radius":
            frame.radii = values
        elif name == "diameter":
            frame.radii = values / 2.0
        elif name not in position_names:
            frame.properties[name] = values
    return frame


def _box(path: str, where: str, lines: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """(3, 3) cell vectors as rows and (3,) origin of a dump's ``BOX BOUNDS`` lines (orthogonal
    or triclinic ``xy xz yz``, whose bounds LAMMPS writes as the tilted box's extent; or a
    general triclinic box, ``BOX BOUNDS abc origin``: each line a cell vector and one
    coordinate of the origin, as LAMMPS since 2024 and OVITO 3.10+'s exporter write it)."""
    try:
        numbers = np.array([[float(v) for v in line.split()] for line in lines[1:4]])
    except ValueError:
        raise ParticleFileError(path, where, "the box bounds are not numbers") from None
    if b"abc origin" in lines[0]:
        if numbers.shape != (3, 4):
            raise ParticleFileError(
                path, where, "the 'abc origin' box bounds are not 3 lines of 4 numbers"
            )
        return np.ascontiguousarray(numbers[:, :3]), np.ascontiguousarray(numbers[:, 3])
    if numbers.shape not in ((3, 2), (3, 3)):
        raise ParticleFileError(path, where, "the box bounds are not 3 lines of 2 or 3 numbers")
    low, high = numbers[:, 0].copy(), numbers[:, 1].copy()
    xy = xz = yz = 0.0
    if numbers.shape[1] == 3:
        xy, xz, yz = numbers[:, 2]
        low[0] -= min(0.0, xy, xz, xy + xz)
        high[0] -= max(0.0, xy, xz, xy + xz)
        low[1] -= min(0.0, yz)
        high[1] -= max(0.0, yz)
    extent = high - low
    box = np.array([[extent[0], 0, 0], [xy, extent[1], 0], [xz, yz, extent[2]]], np.float64)
    return box, low


def _rows(
    path: str, where: str, body: bytes, columns: list[str], count: int
) -> dict[str, np.ndarray]:
    """The ``count`` rows of ``columns`` in ``body``, column by column: (n,) float64, or (n,)
    str for ``element`` and ``type`` (types kept as written, "1", "2", ...)."""
    width = len(columns)
    if width == 0:
        raise ParticleFileError(path, where, "'ITEM: ATOMS' names no columns")
    if "element" in columns:
        tokens = body.split()
        if len(tokens) != count * width:
            raise _truncated(path, where, count, len(tokens), width)
        table = np.array(tokens).reshape(count, width)
        out = {}
        for i, name in enumerate(columns):
            if name in STRING_COLUMNS:
                out[name] = table[:, i].astype(str)
            else:
                out[name] = _numbers(path, where, name, table[:, i])
        return out
    values = np.fromstring(body, dtype=np.float64, sep=" ")
    if len(values) != count * width:
        raise _truncated(path, where, count, len(values), width)
    table = values.reshape(count, width)
    out = {}
    for i, name in enumerate(columns):
        column = np.ascontiguousarray(table[:, i])
        out[name] = column.astype(np.int64).astype(str) if name == "type" else column
    return out


def _numbers(path: str, where: str, name: str, column: np.ndarray) -> np.ndarray:
    try:
        return column.astype(np.float64)
    except ValueError:
        raise ParticleFileError(
            path, where, f"column {name!r} holds a value that is not a number"
        ) from None


def _truncated(path: str, where: str, count: int, found: int, width: int) -> ParticleFileError:
    return ParticleFileError(
        path,
        where,
        f"{count:,} atoms announced but {found / width:,.6g} rows of {width} columns found "
        "(a truncated frame?)",
    )


def _positions(
    path: str, where: str, table: dict[str, np.ndarray], box: np.ndarray, origin: np.ndarray
) -> np.ndarray:
    for triple in POSITION_COLUMNS:
        if all(name in table for name in triple):
            positions = np.stack([table[name] for name in triple], axis=1)
            if triple[0].startswith("xs"):
                positions = origin + positions @ box
            return positions
    raise ParticleFileError(
        path, where, "no position columns (x y z, xu yu zu, xs ys zs or xsu ysu zsu)"
    )
