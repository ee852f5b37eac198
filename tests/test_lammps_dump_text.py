"""The LAMMPS dump's parser (``text_columns``): every number equal bit for bit to CPython's
``float()`` of its text (and to ``np.loadtxt``'s) in every notation LAMMPS and OVITO write,
fields split by any whitespace, rows split across chunks anywhere, text columns as written
(the ``Labels`` that ``np.unique`` makes of their texts), and bad rows refused with the line
that holds them.

Bitwise equality holds on every x86-64 ISA: a number is either one IEEE-754 multiply or divide
of two exactly represented doubles (correctly rounded by SSE2, AVX2 and AVX-512 alike, and no
FMA can be formed from a single operation) or CPython's own correctly rounded conversion."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from embree_rt.scene.particles import ParticleFileError, read_particles, text_columns
from embree_rt.scene.particles.frame import coded
from embree_rt.scene.particles.text_columns import ColumnsError, parse_columns

ROOT = Path(__file__).resolve().parents[1]
# How LAMMPS (``%g``, ``dump_modify format float %20.15g``, ``%.6e``), OVITO (10 significant
# digits) and Python (``repr``) write a float; integers as ``%d``.
NOTATIONS = [
    repr,
    "{:g}".format,
    "{:.10g}".format,
    "{:.15g}".format,
    "{:.17g}".format,
    "{:.6e}".format,
    "{:.3E}".format,
    "{:.5f}".format,
    "{:+.8g}".format,
]
SEPARATORS = st.sampled_from([" ", "  ", "\t", " \t ", "     "])
FLOATS = st.floats(allow_nan=False, allow_infinity=False)


def as_bytes(text: str) -> np.ndarray:
    return np.frombuffer(text.encode(), np.uint8)


def bits(values: np.ndarray) -> np.ndarray:
    return np.asarray(values, np.float64).view(np.int64)


@st.composite
def tables(draw) -> tuple[str, list[list[str]]]:
    """A body of rows of numbers in any notation, any whitespace between and around them."""
    width = draw(st.integers(1, 6))
    count = draw(st.integers(1, 40))
    rows = []
    for _ in range(count):
        fields = []
        for _ in range(width):
            if draw(st.booleans()):
                fields.append(str(draw(st.integers(-(10**12), 10**12))))
            else:
                fields.append(draw(st.sampled_from(NOTATIONS))(draw(FLOATS)))
        rows.append(fields)
    lines = []
    for fields in rows:
        line = draw(st.sampled_from(["", " ", "   "]))
        for field in fields:
            line += field + draw(SEPARATORS)
        lines.append(line if draw(st.booleans()) else line.rstrip())
    ending = draw(st.sampled_from(["", "\n", "\r\n"]))
    return "\n".join(lines) + ending, rows


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(table=tables(), chunk_bytes=st.sampled_from([1, 7, 64, 1 << 18]))
def test_numbers_equal_float_and_loadtxt_bit_for_bit(table, chunk_bytes):
    """Chunks as small as one byte put chunk bounds inside every row; every other field is
    parsed into the row-major block (as positions are), the rest into runs of their own."""
    text, rows = table
    width = len(rows[0])
    together = tuple(range(0, width, 2))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(text_columns, "MIN_CHUNK_BYTES", chunk_bytes)
        result = parse_columns(as_bytes(text), len(rows), np.zeros(width, bool), together)
    expected = np.array([[float(field) for field in row] for row in rows])
    parsed = np.stack(result.columns, axis=1)
    assert np.array_equal(bits(parsed), bits(expected)), (text, parsed, expected)
    assert result.block.flags.c_contiguous
    assert np.array_equal(bits(result.block), bits(expected[:, list(together)]))
    loaded = np.loadtxt(io.StringIO(text), ndmin=2)
    assert np.array_equal(bits(parsed), bits(loaded))


def test_fast_path_and_cast_both_taken_and_exact():
    """Numbers on each side of Clinger's bounds (2^53, 10^22, 18 digits) and what only the
    cast reads (``nan``, ``inf``, ``1e400``): each equal to ``float()``."""
    fields = [
        "9007199254740992",  # 2^53: the fast path
        "9007199254740993",  # 2^53 + 1: rounded by the cast
        "1e22",
        "1e23",
        "1.5e-22",
        "4.9e-324",
        "1e400",
        "-0.0",
        "-0",
        "0e999999",
        "123456789012345678",
        "0.1234567890123456789",
        ".5",
        "5.",
        "+7",
        "nan",
        "-inf",
        "2.2250738585072011e-308",
        "12345678",  # eight digits read at once
        "99999999.99999999",
        "0.000000001",
        "-1234567890123456e-7",
    ]
    columns, _, slow = parse_columns(as_bytes(" ".join(fields)), 1, np.zeros(len(fields), bool))
    parsed = np.array([column[0] for column in columns])
    expected = np.array([float(field) for field in fields])
    assert np.array_equal(bits(parsed), bits(expected))
    assert 0 < slow < len(fields)


def test_text_columns_as_written_and_blank_lines_skipped():
    text = "\n  1 C 0.5  \n\n \t \n2 Fe -1.25e+01\n3   Ow 3\n\n"
    columns = parse_columns(as_bytes(text), 3, np.array([False, True, False])).columns
    assert columns[0].tolist() == [1.0, 2.0, 3.0]
    assert columns[1].values().tolist() == ["C", "Fe", "Ow"]
    assert columns[2].tolist() == [0.5, -12.5, 3.0]


# Names as LAMMPS types, elements and type labels are written, and one in UTF-8 (two bytes,
# each read as the code point it is, as Latin-1 does).
NAMES = st.sampled_from(["1", "2", "3", "10", "C", "Fe", "Ow", "CA_ring", "type_7", "é"])


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    names=st.lists(st.one_of(NAMES, st.text("ABCxyz012_", min_size=1, max_size=12)), min_size=1),
    chunk_bytes=st.sampled_from([1, 13, 1 << 18]),
    per_chunk=st.sampled_from([1, 2, 256]),
)
def test_text_columns_equal_np_unique_of_their_texts(names, chunk_bytes, per_chunk):
    """Each chunk's tables (as small as one name, so that rows are parsed again with tables as
    long as their chunks, and hashed into two slots, so that names collide) merged: the same
    ``Labels`` (sorted names, codes, both dtypes) as ``np.unique`` of the texts gives."""
    text = "".join(f"{row} {name}\t{row / 7!r} {name}\n" for row, name in enumerate(names))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(text_columns, "MIN_CHUNK_BYTES", chunk_bytes)
        patch.setattr(text_columns, "NAMES_PER_CHUNK", per_chunk)
        columns = parse_columns(as_bytes(text), len(names), np.array([False, True, False, True]))
    as_read = [name.encode().decode("latin-1") for name in names]
    expected = coded(as_read)
    for labels in (columns.columns[1], columns.columns[3]):
        assert labels.values().tolist() == as_read
        assert labels.names.dtype == expected.names.dtype
        assert labels.names.tolist() == expected.names.tolist()
        assert labels.codes.dtype == expected.codes.dtype
        assert np.array_equal(labels.codes, expected.codes)
    assert columns.columns[0].tolist() == list(range(len(names)))


@pytest.mark.parametrize(
    ("distinct", "per_chunk", "dtype"), [(600, 256, np.uint16), (70000, 256, np.uint32)]
)
def test_many_names_widen_the_codes(distinct, per_chunk, dtype):
    """600 names, each chunk's few enough for its one-byte table, merge into two-byte codes;
    70,000 in one chunk outgrow the table and take the parse round again."""
    names = [f"t{row}" for row in range(distinct)]
    text = "".join(f"{name} {row}\n" for row, name in enumerate(names))
    tables = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(text_columns, "MIN_CHUNK_BYTES", 1 << 10 if distinct < 1000 else 1 << 30)
        patch.setattr(text_columns, "NAMES_PER_CHUNK", per_chunk)
        made = text_columns.name_tables
        patch.setattr(text_columns, "name_tables", lambda *a: tables.append(a) or made(*a))
        labels = parse_columns(as_bytes(text), distinct, np.array([True, False])).columns[0]
    assert len(tables) == (1 if distinct < 1000 else 2)
    assert labels.codes.dtype == dtype
    assert labels.values().tolist() == names
    assert labels.names.tolist() == sorted(names)


@pytest.mark.parametrize(
    ("text", "count", "problem"),
    [
        ("1 2\n3 4\n", 3, ("rows", 2, 3)),
        ("1 2\n3 4\n5 6\n", 2, ("rows", 3, 2)),
        ("1 2\n3\n", 2, ("fields", 1, 2)),
        ("1 2\n3 4 5\n", 2, ("fields", 3, 2)),
    ],
)
def test_rows_of_the_wrong_count_or_width_refused(text, count, problem):
    with pytest.raises(ColumnsError) as caught:
        parse_columns(as_bytes(text), count, np.zeros(2, bool))
    got = caught.value.problem
    assert (got.kind, got.found, got.expected) == problem
    if got.kind == "fields":
        assert got.offset == text.index("\n") + 1


def test_a_field_that_is_no_number_refused_with_its_offset():
    text = "1 2\n3 x4\n"
    with pytest.raises(ColumnsError) as caught:
        parse_columns(as_bytes(text), 2, np.zeros(2, bool))
    problem = caught.value.problem
    assert (problem.kind, problem.text, problem.field) == ("number", "x4", 1)
    assert problem.offset == text.index("x4")


@pytest.mark.parametrize("position", range(9))
@pytest.mark.parametrize("byte", ["/", ":"])
def test_the_bytes_beside_the_digits_end_an_eight_digit_run(position, byte):
    """``/`` and ``:`` stand just below and above the digits in ASCII: at any place of an
    eight-digit run they make the field no number, as ``float()`` finds it."""
    text = "1234567890"[:position] + byte + "12345678"
    with pytest.raises(ValueError):
        float(text)
    with pytest.raises(ColumnsError) as caught:
        parse_columns(as_bytes(f"1 {text}\n"), 1, np.zeros(2, bool))
    assert (caught.value.problem.kind, caught.value.problem.text) == ("number", text)


def write_dump(path: Path, rows: list[str], columns: str) -> None:
    head = f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{len(rows)}\n"
    head += "ITEM: BOX BOUNDS pp pp pp\n" + "0 10\n" * 3 + f"ITEM: ATOMS {columns}\n"
    path.write_text(head + "".join(row + "\n" for row in rows))


def test_aligned_dump_reads_as_the_plain_one(tmp_path):
    """``dump_modify format line "%6d %3d %14.8f %14.8f %14.8f"`` pads fields with runs of
    spaces; LAMMPS's default ends each row with one space."""
    rng = np.random.default_rng(5)
    table = rng.uniform(-5, 15, (30, 3))
    types = rng.integers(1, 4, 30)
    plain = [f"{i + 1} {t} " + " ".join(f"{v:.8f}" for v in row) + " " for i, (t, row) in
             enumerate(zip(types, table, strict=True))]  # fmt: skip
    aligned = [f"{i + 1:6d} {t:3d} " + " ".join(f"{v:14.8f}" for v in row) for i, (t, row) in
               enumerate(zip(types, table, strict=True))]  # fmt: skip
    write_dump(tmp_path / "p.lammpstrj", plain, "id type x y z")
    write_dump(tmp_path / "a.lammpstrj", aligned, "id type x y z")
    first, second = (
        read_particles(tmp_path / "p.lammpstrj"),
        read_particles(tmp_path / "a.lammpstrj"),
    )
    reference = np.array([[float(f"{v:.8f}") for v in row] for row in table])
    assert np.array_equal(bits(first.positions), bits(reference))
    assert np.array_equal(bits(second.positions), bits(reference))
    assert second.types.tolist() == [str(t) for t in types]


def test_no_number_names_file_line_and_column(tmp_path):
    path = tmp_path / "b.lammpstrj"
    write_dump(path, ["1 1 0 0 0", "2 1 0.5 O.5 1"], "id type x y z")
    with pytest.raises(ParticleFileError, match=r"frame 0, line 11: column 'y' holds 'O.5'"):
        read_particles(path)


def test_no_number_on_the_command_line_one_line_exit_2(tmp_path):
    write_dump(tmp_path / "b.lammpstrj", ["1 1 0 0 0", "2 1 0.5 1 1 7"], "id type x y z")
    done = subprocess.run(
        [sys.executable, "-m", "embree_rt", "render", "b.lammpstrj", "-o", "o.png"],
        cwd=tmp_path,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "b.lammpstrj" in lines[0] and "line 11" in lines[0], lines
    assert not (tmp_path / "o.png").exists()
