"""Rows of whitespace-separated fields parsed into columns on all cores (numba): numbers as
float64 equal bit for bit to Python's ``float()`` of their text, text fields as ``Labels``
(the distinct texts and a code a row).

The body is split into line-aligned chunks, one numba task each: a first pass counts each
chunk's rows, a second parses them into their rows. A number is parsed exactly where one IEEE
operation suffices (Clinger's fast path: at most 2^53 as an integer of its digits and a power
of ten of at most 22, one exact multiply or divide, correctly rounded on every x86-64 ISA as
numba compiles it without fast-math); any other text (17 significant digits, ``1e300``,
``nan``, a typo) is handed to NumPy's bytes-to-float64 cast, which is CPython's correctly
rounded ``float()``, and refused where that refuses it. The text is read in place (a memory
map of the file), so a frame needs its columns' memory and no copy of its text.

A text field (a type, an element) is entered in its chunk's table of names as the parse meets
it (an open-addressing hash of its bytes), and the row keeps the name's one-byte code in that
table; the tables are then merged into the sorted names and each row's code recoded in place.
So 1e7 types take 10 MB where their strings and ``np.unique``'s sort took some 500 MB of fresh
pages. A chunk that meets more than 256 names is parsed again with a table as long as its rows.
"""

from __future__ import annotations

import mmap
from typing import NamedTuple

import numpy as np
from numba import get_num_threads, njit, prange

from embree_rt.scene.particles.frame import Labels, code_dtype

# Exact powers of ten: 10^22 is the largest that a float64 holds exactly.
POWERS_OF_TEN = np.array([10.0**k for k in range(23)])
MAX_EXACT_MANTISSA = 1 << 53
# Chunks per numba thread (the last chunks' rows balance uneven lines) and the smallest chunk.
CHUNKS_PER_THREAD = 4
MIN_CHUNK_BYTES = 1 << 18
# Fields that miss the fast path are cast by NumPy this many at a time (bounded memory).
SLOW_BATCH = 1 << 20
# Names a chunk's table holds while its rows' codes take one byte each.
NAMES_PER_CHUNK = 256
# FNV-1a, 64 bits: the hash of a text field's bytes.
FNV_OFFSET = np.uint64(14695981039346656037)
FNV_PRIME = np.uint64(1099511628211)

NEWLINE = 10


class ColumnsProblem(NamedTuple):
    """Why rows could not be parsed: ``kind`` "rows" (``found`` rows where ``expected`` were
    announced), "fields" (the row at byte ``offset`` has ``found`` fields, not ``expected``) or
    "number" (``text``, field ``field`` of a row, at byte ``offset``, is not a number)."""

    kind: str
    offset: int
    found: int = 0
    expected: int = 0
    text: str = ""
    field: int = -1


class ColumnsError(ValueError):
    """Rows that are not ``count`` rows of ``width`` fields; ``problem`` says where."""

    def __init__(self, problem: ColumnsProblem) -> None:
        super().__init__(problem.kind)
        self.problem = problem


class NameTables(NamedTuple):
    """Each text field's names in each chunk's table, and each row's code in its chunk's table.

    ``codes`` (text fields, n) uint8 (or uint32 where a table outgrows ``NAMES_PER_CHUNK``):
    row r's text of field k is entry ``codes[k, r]`` of its chunk's table of field k. Chunk c's
    table is entries ``table_at[c]`` to ``table_at[c + 1]`` ((chunks + 1,) int64) of ``first``
    (text fields, entries) int64, the byte offset of each name's first occurrence, and
    ``length`` (same shape) int64, its length; ``size`` (text fields, chunks) int64 how many
    entries each table fills. ``slots`` (text fields, slot entries) int64 hashes the names,
    chunk c's from ``slot_at[c]`` to ``slot_at[c + 1]`` (a power of two, at least twice its
    table): a name's entry + 1, or 0. ``full`` (chunks,) bool: the chunk met a name its table
    had no room for (its rows' codes are then wrong)."""

    codes: np.ndarray
    first: np.ndarray
    length: np.ndarray
    size: np.ndarray
    table_at: np.ndarray
    slots: np.ndarray
    slot_at: np.ndarray
    full: np.ndarray


def mapped_empty(shape: int | tuple[int, ...], dtype: np.typing.DTypeLike) -> np.ndarray:
    """An uninitialised array of ``shape`` and ``dtype`` in an anonymous memory map of its own
    (unmapped when the last array over it goes), for the parse's outputs. NumPy asks the kernel
    to back any array of 4 MB or more with transparent huge pages, and where THP's ``defrag``
    is ``madvise`` (the kernel's default) each 2 MB page's first write then waits for the
    kernel to compact memory: a 1e7-row dump's 330 MB of columns cost 2-4 s of system time
    that way, 0.7 s in 4 kB pages."""
    dtype = np.dtype(dtype)
    count = int(np.prod(shape))
    pages = mmap.mmap(-1, max(1, count * dtype.itemsize))
    return np.frombuffer(pages, dtype, count).reshape(shape)


def name_tables(text_count: int, count: int, capacity: np.ndarray) -> NameTables:
    """Empty ``NameTables`` for ``text_count`` text fields of ``count`` rows, chunk c's table
    ``capacity[c]`` ((chunks,) int64) names long."""
    table_at = np.concatenate(([0], np.cumsum(capacity))).astype(np.int64)
    hash_sizes = [1 << max(1, int(2 * size - 1).bit_length()) for size in capacity]
    slot_at = np.concatenate(([0], np.cumsum(hash_sizes))).astype(np.int64)
    wide = capacity.max(initial=0) > NAMES_PER_CHUNK
    return NameTables(
        codes=mapped_empty((text_count, count), np.uint32 if wide else np.uint8),
        first=np.empty((text_count, table_at[-1]), np.int64),
        length=np.empty((text_count, table_at[-1]), np.int64),
        size=np.zeros((text_count, len(capacity)), np.int64),
        table_at=table_at,
        slots=np.zeros((text_count, slot_at[-1]), np.int64),
        slot_at=slot_at,
        full=np.zeros(len(capacity), np.bool_),
    )


class ParsedRows(NamedTuple):
    """``columns`` one entry a field: (n,) float64, or ``Labels`` for a text field (its texts
    as written, each byte a code point); ``block`` the fields asked for together as one (n, k)
    C-contiguous float64 array (whose columns those fields' entries view); ``slow`` how many
    numbers missed the fast path."""

    columns: list[np.ndarray]
    block: np.ndarray
    slow: int


def parse_columns(
    data: np.ndarray, count: int, is_text: np.ndarray, together: tuple[int, ...] = ()
) -> ParsedRows:
    """The ``count`` rows of ``data`` ((m,) uint8, lines of whitespace-separated fields, blank
    lines ignored), field by field: float64, or ``Labels`` where ``is_text`` ((width,) bool)
    says so; the numeric fields ``together`` (indexes) written row by row into one (count, k)
    block, as positions are wanted, so that no copy of them is made. Raises ``ColumnsError``
    naming the first problem's byte offset in ``data``."""
    width = len(is_text)
    numeric = [j for j in range(width) if not is_text[j] and j not in together]
    # Field j's number in row r goes to flat[slots[j] + r * strides[j]]: the block first,
    # then one run of ``count`` a numeric field; a text field's slot is -1 - its text index.
    slots = np.zeros(width, np.int64)
    strides = np.ones(width, np.int64)
    for k, j in enumerate(together):
        slots[j], strides[j] = k, len(together)
    for k, j in enumerate(numeric):
        slots[j] = (len(together) + k) * count
    slots[is_text] = -1 - np.arange(int(is_text.sum()))
    bounds = chunk_bounds(data, _chunk_count(len(data)))
    flat = mapped_empty((len(together) + len(numeric)) * count, np.float64)
    text_count = int(is_text.sum())
    chunks = len(bounds) - 1
    slow = np.zeros(chunks, np.int64)
    blank = np.zeros(chunks, np.int64)
    problems = np.full((chunks, 2), -1, np.int64)
    # Rows are first taken as lines (one vectorised pass); a chunk that meets a blank line
    # sends the parse round again with the rows counted exactly, and one whose names outgrow
    # its table, with tables as long as their chunks' rows.
    rows = count_lines(data, bounds)
    exact = False
    capacity = np.full(chunks, NAMES_PER_CHUNK, np.int64)
    while True:
        if int(rows.sum()) != count:
            if exact:
                raise ColumnsError(ColumnsProblem("rows", len(data), int(rows.sum()), count))
            rows, exact = count_rows(data, bounds), True
            continue
        first_row = np.concatenate(([0], np.cumsum(rows)[:-1])).astype(np.int64)
        names = name_tables(text_count, count, capacity)
        parse_rows(
            data, bounds, first_row, count, slots, strides, POWERS_OF_TEN, flat, names, slow,
            blank, problems,
        )  # fmt: skip
        if blank.any() and not exact:
            rows, exact = count_rows(data, bounds), True
            continue
        bad = np.flatnonzero(problems[:, 0] >= 0)
        if len(bad):
            offset, fields = problems[bad[0]]
            raise ColumnsError(ColumnsProblem("fields", int(offset), int(fields), width))
        if not names.full.any():
            break
        capacity = np.maximum(rows, 1)
    slow_total = int(slow.sum())
    if slow_total:
        _cast_slow(data, bounds, first_row, slots, strides, slow, flat)
    block = flat[: len(together) * count].reshape(count, len(together))
    columns = []
    for j in range(width):
        if is_text[j]:
            columns.append(_labels(data, names, -1 - slots[j], first_row, rows))
        elif j in together:
            columns.append(block[:, together.index(j)])
        else:
            columns.append(flat[slots[j] : slots[j] + count])
    return ParsedRows(columns, block, slow_total)


def _chunk_count(size: int) -> int:
    return int(max(1, min(get_num_threads() * CHUNKS_PER_THREAD, size // MIN_CHUNK_BYTES)))


def _cast_slow(
    data: np.ndarray,
    bounds: np.ndarray,
    first_row: np.ndarray,
    slots: np.ndarray,
    strides: np.ndarray,
    slow: np.ndarray,
    flat: np.ndarray,
) -> None:
    """Fill the numbers that missed the fast path with NumPy's cast of their text, in
    batches; raises ``ColumnsError`` at the first text that is not a number."""
    first_slow = np.concatenate(([0], np.cumsum(slow)[:-1])).astype(np.int64)
    starts, ends, rows, fields = (mapped_empty(int(slow.sum()), np.int64) for _ in range(4))
    slow_fields(
        data, bounds, first_row, slots, POWERS_OF_TEN, slow, first_slow, starts, ends, rows, fields
    )
    for at in range(0, len(starts), SLOW_BATCH):
        part = slice(at, at + SLOW_BATCH)
        width = int((ends[part] - starts[part]).max())
        texts = gather(data, starts[part], ends[part] - starts[part], width).view(f"S{width}")[:, 0]
        try:
            values = texts.astype(np.float64)
        except ValueError:
            for k, text in enumerate(texts):
                try:
                    float(text)
                except ValueError:
                    shown = text.decode("ascii", "replace")
                    raise ColumnsError(
                        ColumnsProblem(
                            "number", int(starts[at + k]), text=shown, field=int(fields[at + k])
                        )
                    ) from None
            raise
        flat[slots[fields[part]] + rows[part] * strides[fields[part]]] = values


def _labels(
    data: np.ndarray, names: NameTables, field: int, first_row: np.ndarray, rows: np.ndarray
) -> Labels:
    """Text field ``field``'s ``Labels``: its chunks' tables merged into the sorted names
    (``np.unique`` of their texts) and each row's code recoded to them, in place where the
    codes' dtype stays."""
    size = names.size[field]
    entries = np.concatenate(
        [np.arange(at, at + filled) for at, filled in zip(names.table_at[:-1], size, strict=True)]
    ).astype(np.int64)
    texts = _texts(data, names.first[field, entries], names.length[field, entries])
    distinct, inverse = np.unique(texts, return_inverse=True)
    merged = np.zeros(names.table_at[-1], np.int64)
    merged[entries] = inverse.reshape(-1)
    codes = names.codes[field]
    dtype = code_dtype(len(distinct))
    out = codes if codes.dtype == dtype else mapped_empty(len(codes), dtype)
    recode(codes, first_row, rows, names.table_at, merged, out)
    return Labels(distinct, out)


def _texts(data: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """(n,) str of the fields at ``starts`` of ``lengths``, each byte a code point (Latin-1,
    so ASCII as written): NumPy's own bytes-to-str cast took 0.4 s over 1e6 one-letter types."""
    width = max(1, int(lengths.max(initial=0)))
    code_points = gather(data, starts, lengths, width).astype(np.uint32)
    return code_points.view(f"U{width}")[:, 0]


@njit(inline="always")
def _byte(data: np.ndarray, at: int) -> np.uint8:
    """``data[at]`` for ``at`` known to be in range: an unsigned index spares numba's check of
    a signed one for a negative value, which made the parse 1.7x slower."""
    return data[np.uint64(at)]


@njit(cache=True, nogil=True)
def chunk_bounds(data: np.ndarray, chunks: int) -> np.ndarray:
    """(chunks + 1,) int64 byte offsets splitting ``data`` after newlines (some chunks may be
    empty)."""
    bounds = np.empty(chunks + 1, np.int64)
    bounds[0] = 0
    size = len(data)
    for c in range(1, chunks):
        at = max(size * c // chunks, bounds[c - 1])
        while at < size and (at == 0 or _byte(data, at - 1) != NEWLINE):
            at += 1
        bounds[c] = at
    bounds[chunks] = size
    return bounds


@njit(parallel=True, cache=True, nogil=True)
def count_lines(data: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(chunks,) int64: the lines of each chunk, blank or not. Written so that LLVM
    vectorises it (a loop from 0 over a slice, the sum of int64s): 5x faster than a loop over
    ``range(start, end)`` of ``data``."""
    chunks = len(bounds) - 1
    lines = np.zeros(chunks, np.int64)
    for c in prange(chunks):
        chunk = data[bounds[c] : bounds[c + 1]]
        count = 0
        for at in range(len(chunk)):
            count += np.int64(chunk[at] == NEWLINE)
        if bounds[c + 1] > bounds[c] and data[bounds[c + 1] - 1] != NEWLINE:
            count += 1
        lines[c] = count
    return lines


@njit(inline="always")
def _is_space(byte: np.uint8) -> bool:
    return byte == 32 or byte == 9 or byte == 13 or byte == 11 or byte == 12


@njit(parallel=True, cache=True, nogil=True)
def count_rows(data: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(chunks,) int64: the non-blank lines of each chunk."""
    chunks = len(bounds) - 1
    rows = np.zeros(chunks, np.int64)
    for c in prange(chunks):
        count = 0
        filled = False
        for at in range(bounds[c], bounds[c + 1]):
            byte = _byte(data, at)
            if byte == NEWLINE:
                if filled:
                    count += 1
                filled = False
            elif not _is_space(byte):
                filled = True
        if filled:
            count += 1
        rows[c] = count
    return rows


@njit(inline="always")
def _is_separator(byte: np.uint8) -> bool:
    return byte == NEWLINE or _is_space(byte)


@njit(inline="always")
def _eight_bytes(data: np.ndarray, at: int) -> np.uint64:
    """Bytes ``at`` to ``at + 8`` of ``data`` as one little-endian uint64 (LLVM merges the
    eight loads into one)."""
    word = np.uint64(0)
    for k in range(8):
        word |= np.uint64(_byte(data, at + k)) << np.uint64(8 * k)
    return word


@njit(inline="always")
def _all_digits(word: np.uint64) -> bool:
    """Whether each byte of ``word`` is an ASCII digit: its high nibble 3, and adding 6
    carries no byte past 9 into the next nibble."""
    high = np.uint64(0xF0F0F0F0F0F0F0F0)
    return (word & high) == np.uint64(0x3030303030303030) and (
        (word + np.uint64(0x0606060606060606)) & high
    ) == np.uint64(0x3030303030303030)


@njit(inline="always")
def _eight_digits(word: np.uint64) -> np.uint64:
    """The integer the eight ASCII digits of ``word`` write (its first byte the most
    significant digit): pairs, then fours, then the eight, each one multiply."""
    word = ((word & np.uint64(0x0F0F0F0F0F0F0F0F)) * np.uint64(2561)) >> np.uint64(8)
    word = ((word & np.uint64(0x00FF00FF00FF00FF)) * np.uint64(6553601)) >> np.uint64(16)
    return ((word & np.uint64(0x0000FFFF0000FFFF)) * np.uint64(42949672960001)) >> np.uint64(32)


@njit(inline="always")
def _digits(data: np.ndarray, at: int, limit: int, value: int, count: int) -> tuple[int, int, int]:
    """The decimal digits from byte ``at`` (up to ``limit``) appended to the integer ``value``
    of ``count`` digits: the new integer (wrapping past 19 digits, which the caller counts),
    the new digit count and the byte after the digits. Eight digits at a time while eight
    bytes are digits (SWAR, as fast_float does: three multiplies rather than eight dependent
    multiply-adds), then one at a time."""
    while at + 8 <= limit:
        word = _eight_bytes(data, at)
        if not _all_digits(word):
            break
        value = value * 100000000 + np.int64(_eight_digits(word))
        count += 8
        at += 8
    while at < limit and 48 <= _byte(data, at) <= 57:
        value = value * 10 + (_byte(data, at) - 48)
        count += 1
        at += 1
    return value, count, at


@njit(inline="always")
def scan_number(
    data: np.ndarray, start: int, limit: int, powers: np.ndarray
) -> tuple[float, bool, int]:
    """The field starting at byte ``start`` (ending at a separator or ``limit``): its float64,
    True where Clinger's fast path gives it exactly (``[+-]digits[.digits][(e|E)[+-]digits]``
    with at most 18 digits, their integer at most 2^53, the power of ten within 22; else
    0.0 and False), and the byte after it."""
    at = start
    negative = False
    if _byte(data, at) == 45 or _byte(data, at) == 43:  # - +
        negative = _byte(data, at) == 45
        at += 1
    mantissa, digits, at = _digits(data, at, limit, 0, 0)
    exponent = 0
    if at < limit and _byte(data, at) == 46:  # .
        whole = digits
        mantissa, digits, at = _digits(data, at + 1, limit, mantissa, digits)
        exponent = whole - digits
    exact = 0 < digits <= 18
    if at < limit and (_byte(data, at) == 101 or _byte(data, at) == 69):  # e E
        at += 1
        exponent_negative = False
        if at < limit and (_byte(data, at) == 45 or _byte(data, at) == 43):
            exponent_negative = _byte(data, at) == 45
            at += 1
        written, exponent_digits, at = _digits(data, at, limit, 0, 0)
        exact = exact and 0 < exponent_digits <= 4
        exponent += -written if exponent_negative else written
    if at < limit and not _is_separator(_byte(data, at)):
        exact = False
        while at < limit and not _is_separator(_byte(data, at)):
            at += 1
    if not exact:
        return 0.0, False, at
    if mantissa == 0:
        return (-0.0 if negative else 0.0), True, at
    if mantissa > MAX_EXACT_MANTISSA or exponent > 22 or exponent < -22:
        return 0.0, False, at
    value = float(mantissa)
    value = value * powers[exponent] if exponent >= 0 else value / powers[-exponent]
    return (-value if negative else value), True, at


@njit(parallel=True, cache=True, nogil=True)
def parse_rows(
    data: np.ndarray,
    bounds: np.ndarray,
    first_row: np.ndarray,
    total: int,
    slots: np.ndarray,
    strides: np.ndarray,
    powers: np.ndarray,
    flat: np.ndarray,
    names: NameTables,
    slow: np.ndarray,
    blank: np.ndarray,
    problems: np.ndarray,
) -> None:
    """Each chunk's rows, from row ``first_row[c]`` on (``total`` rows in all), into ``flat``
    (float64: field j of row r at ``slots[j] + r * strides[j]``; NaN where a number missed
    the fast path, counted in ``slow``) and ``names`` (text field j is ``names``' field
    ``-1 - slots[j]``). Blank lines are counted in ``blank`` (then ``first_row`` may be wrong,
    and rows past ``total`` are not written); a chunk's first line of the wrong field count is
    left in ``problems[c]`` as (its byte offset, fields found)."""
    width = len(slots)
    # The tables' arrays are taken out of ``names`` here: a prange body's stores through a
    # named tuple's arrays are lost (numba issue 7135). A function of its own for the chunk's
    # rows, called from the body, made the parse 1.5x slower, and a call a row to a function
    # that takes ``names`` cost 70 ns a row.
    codes, first, length, size, table_at, name_slots, slot_at, full = names
    for c in prange(len(bounds) - 1):
        row = first_row[c]
        at = bounds[c]
        end = bounds[c + 1]
        slow_count = 0
        blank_count = 0
        while at < end:
            line = at
            field = 0
            while at < end and _byte(data, at) != NEWLINE:
                if _is_space(_byte(data, at)):
                    at += 1
                    continue
                if field >= width or row >= total:
                    field += 1
                    while at < end and not _is_separator(_byte(data, at)):
                        at += 1
                    continue
                slot = slots[field]
                if slot >= 0:
                    value, exact, at = scan_number(data, at, end, powers)
                    if not exact:
                        value = np.nan
                        slow_count += 1
                    flat[slot + row * strides[field]] = value
                else:
                    at, entry = enter_name(
                        data, at, end, -1 - slot, c, first, length, size, table_at, name_slots,
                        slot_at,
                    )  # fmt: skip
                    if entry < 0:
                        full[c] = True
                    else:
                        codes[-1 - slot, row] = entry
                field += 1
            at += 1
            if field == 0 or row >= total:
                blank_count += 1
                continue
            if field != width:
                problems[c, 0] = line
                problems[c, 1] = field
                break
            row += 1
        slow[c] = slow_count
        blank[c] = blank_count


@njit(inline="always")
def enter_name(
    data: np.ndarray,
    start: int,
    end: int,
    field: int,
    chunk: int,
    first: np.ndarray,
    length: np.ndarray,
    size: np.ndarray,
    table_at: np.ndarray,
    name_slots: np.ndarray,
    slot_at: np.ndarray,
) -> tuple[int, int]:
    """The text field ``field`` from byte ``start`` (to a separator or ``end``) looked up in
    chunk ``chunk``'s table (``NameTables``' arrays of those names, ``name_slots`` its
    ``slots``), entered there if new: the byte after the field and its entry (-1 where the
    table has no room)."""
    at = start
    hashed = FNV_OFFSET
    while at < end and not _is_separator(_byte(data, at)):
        hashed = (hashed ^ np.uint64(_byte(data, at))) * FNV_PRIME
        at += 1
    span = at - start
    base = table_at[chunk]
    slot_base = slot_at[chunk]
    mask = slot_at[chunk + 1] - slot_base - 1
    slot = np.int64(hashed & np.uint64(mask))
    while True:
        entry = name_slots[field, slot_base + slot] - 1
        if entry < 0:
            entry = size[field, chunk]
            if entry == table_at[chunk + 1] - base:
                return at, -1
            first[field, base + entry] = start
            length[field, base + entry] = span
            name_slots[field, slot_base + slot] = entry + 1
            size[field, chunk] = entry + 1
            return at, entry
        if length[field, base + entry] == span and _same_bytes(
            data, first[field, base + entry], start, span
        ):
            return at, entry
        slot = (slot + 1) & mask


@njit(inline="always")
def _same_bytes(data: np.ndarray, first: int, second: int, length: int) -> bool:
    """Whether the ``length`` bytes at ``first`` and at ``second`` are the same."""
    for k in range(length):  # noqa: SIM110 (numba compiles no all() of a generator)
        if _byte(data, first + k) != _byte(data, second + k):
            return False
    return True


@njit(parallel=True, cache=True, nogil=True)
def recode(
    codes: np.ndarray,
    first_row: np.ndarray,
    rows: np.ndarray,
    table_at: np.ndarray,
    merged: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out[r] = merged[table_at[c] + codes[r]]`` for chunk c's rows (``rows[c]`` from
    ``first_row[c]``): (n,) codes into each chunk's table turned into codes into the merged
    names (``out`` may be ``codes``)."""
    for c in prange(len(rows)):
        base = table_at[c]
        for r in range(first_row[c], first_row[c] + rows[c]):
            out[r] = merged[base + codes[r]]


@njit(parallel=True, cache=True, nogil=True)
def slow_fields(
    data: np.ndarray,
    bounds: np.ndarray,
    first_row: np.ndarray,
    slots: np.ndarray,
    powers: np.ndarray,
    slow: np.ndarray,
    first_slow: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    rows: np.ndarray,
    fields: np.ndarray,
) -> None:
    """Where the numbers that missed the fast path lie (after ``parse_rows`` found every row
    whole): their byte ranges, rows and fields, chunk ``c``'s ``slow[c]`` from
    ``first_slow[c]`` on."""
    for c in prange(len(bounds) - 1):
        if slow[c] == 0:
            continue
        out = first_slow[c]
        row = first_row[c]
        at = bounds[c]
        end = bounds[c + 1]
        while at < end:
            field = 0
            while at < end and _byte(data, at) != NEWLINE:
                if _is_space(_byte(data, at)):
                    at += 1
                    continue
                start = at
                exact = True
                if slots[field] >= 0:
                    exact, at = scan_number(data, at, end, powers)[1:]
                else:
                    while at < end and not _is_separator(_byte(data, at)):
                        at += 1
                if not exact:
                    starts[out] = start
                    ends[out] = at
                    rows[out] = row
                    fields[out] = field
                    out += 1
                field += 1
            at += 1
            if field > 0:
                row += 1


@njit(cache=True, nogil=True)
def gather(data: np.ndarray, starts: np.ndarray, lengths: np.ndarray, width: int) -> np.ndarray:
    """(n, width) uint8: ``data[starts[i]:starts[i] + lengths[i]]`` each, NUL-padded (as
    NumPy's ``S`` dtype reads it)."""
    out = np.zeros((len(starts), width), np.uint8)
    for i in range(len(starts)):
        for k in range(min(lengths[i], width)):
            out[i, k] = _byte(data, starts[i] + k)
    return out


@njit(cache=True, nogil=True)
def line_number(data: np.ndarray, offset: int) -> int:
    """The 1-based line of byte ``offset`` in ``data``."""
    lines = 1
    for at in range(min(offset, len(data))):
        if _byte(data, at) == NEWLINE:
            lines += 1
    return lines
