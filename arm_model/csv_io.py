"""Fast, strict CSV reading and writing for large files (millions of rows).

Reading: the file is read in blocks of whole lines. In a block whose lines all have the header's
cell count (found from the separator positions), the numeric cells written as plain decimals
(``-12.5``, ``3``, at most 2**53 as an integer mantissa) are read by integer arithmetic on numpy
arrays, exactly as Python's ``float`` reads them; a few other cells are read one by one, a block
of many (exponents) by numpy's C reader (``np.loadtxt``). Anything these do not accept exactly (a
quoted cell, a wrong cell count, a blank-looking line) sends the block to the cell-by-cell reader,
which either parses it the same way or raises the located :class:`InputError` (file, line,
column). All paths accept the same numbers: ASCII decimals with an optional exponent (``12.5``,
``-3e-4``) and ``nan``/``inf`` (callers refuse non-finite values with their location), padded with ASCII white
space only; never ``4_5`` (Python's ``float`` would read 45), hex, non-ASCII digits or a no-break space.

Writing: fixed-decimal columns (``%.6f``) are formatted by integer arithmetic on numpy arrays into
a character matrix, transposed to text order, and the unused characters dropped; other formats
fall back to Python's ``%`` formatting.
"""
from __future__ import annotations

import csv
import io
import math
import os
import re
import stat
import warnings
from dataclasses import dataclass
from decimal import ROUND_HALF_EVEN, Decimal
from pathlib import Path

import numpy as np

from .errors import InputError, decode_text, open_input, text_lines

__all__ = ["parse_number", "SPACE", "blank_record", "csv_records", "CsvBlock", "iter_csv_blocks", "csv_spans",
           "format_csv", "format_row", "label_rows"]

_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:nan|inf|infinity)",
                     re.IGNORECASE)
BLOCK_BYTES = 1 << 22          # 4 MiB (about 37 000 points rows): small temporaries, few page faults
PARALLEL_BYTES = 1 << 25       # 32 MiB (about 300 000 points rows): a file worth reading in parallel parts


#: the white space a number's cell may hold around it: ASCII only (``str.strip()`` also takes a no-break space, an
#: ideographic space or NEL for white space, and a cell '12.5\xa0' read as 12.5 where '１２.5' was refused)
SPACE = " \t\r\n\f\v"


def parse_number(cell: str) -> float | None:
    """The number in a cell (ASCII white space around it dropped, :data:`SPACE`), or None if it is not one (see
    the module doc)."""
    cell = cell.strip(SPACE)
    return float(cell) if _NUMBER.fullmatch(cell) else None


_SEPARATORS = " \t\r\f\v,"


def blank_record(line: str) -> bool:
    """True for a line that holds no value: empty, white space, or only commas between blank (or quoted
    blank, ``""``) cells, as a spreadsheet writes an empty row (``,,,,``). Every reader of the toolkit's CSV
    (files and live streams) skips such a line as a blank one, never counting it as a sample or a bad line."""
    rest = line.strip(_SEPARATORS)
    if not rest:
        return True
    if rest[0] != '"':
        return False
    try:
        return not any(c.strip() for c in next(csv.reader([line], strict=True)))
    except csv.Error:
        return False


def csv_records(text: str, path: str, first_line: int = 1) -> list[tuple[int, list[str]]]:
    """Non-blank CSV records (:func:`blank_record`) with their physical line; a record may not span lines."""
    out = []
    for no, line in enumerate(text_lines(text), start=first_line):
        if blank_record(line):
            continue
        try:
            rec = next(csv.reader([line], strict=True))
        except csv.Error as exc:
            raise InputError(f"not valid CSV: {exc}", path, no) from None
        out.append((no, rec))
    return out


@dataclass
class CsvBlock:
    """Rows of one block: ``lines`` (n,) physical 1-based lines, ``numbers`` (n, k) in the order of
    the requested numeric columns (file units, not checked for finiteness), ``texts`` (n, m) the
    stripped text cells (object array)."""
    lines: np.ndarray
    numbers: np.ndarray
    texts: np.ndarray


def _empty_cell_error(cell: str, path, no, name):
    return InputError(f"expected a number, got {cell!r}" if cell else "empty cell where a number is expected",
                      path, no, name)


def _slow_block(text: str, path: str, first_line: int, header: list[str], num_idx, txt_idx) -> CsvBlock:
    recs = csv_records(text, path, first_line)
    n = len(recs)
    numbers = np.empty((n, len(num_idx)))
    texts = np.empty((n, len(txt_idx)), dtype=object)
    for i, (no, r) in enumerate(recs):
        if len(r) != len(header):
            raise InputError(f"{len(r)} cells where the header has {len(header)} columns", path, no)
        for k, c in enumerate(num_idx):
            cell = r[c].strip(SPACE)
            v = parse_number(cell)
            if v is None:
                raise _empty_cell_error(cell, path, no, header[c])
            numbers[i, k] = v
        for k, c in enumerate(txt_idx):
            texts[i, k] = r[c].strip()
    return CsvBlock(np.array([no for no, _ in recs], dtype=np.int64), numbers, texts)


_POW10_U = np.array([10 ** k for k in range(20)], dtype=np.uint64)
_DIVISORS = np.array([10.0 ** k for k in range(20)] + [-10.0 ** k for k in range(20)])   # the sign too
_CELLS = 65536                 # cells parsed at a time: the temporaries stay in the cache
_EXACT = 2 ** 53               # a mantissa up to this is a double exactly


def _u64(x) -> np.uint64:
    return np.uint64(x)


def _windows(arr: np.ndarray, width: int, before: bool = True) -> np.ndarray:
    """(len(arr) + 1, width) read-only view of ``arr``: row ``p`` holds ``arr[p - width:p]``
    (``before``) or ``arr[p:p + width]``, zeros outside ``arr``. Indexing rows of it copies the cells
    of a block in one pass."""
    pad = np.zeros(len(arr) + width, np.uint8)
    if before:
        pad[width:] = arr
    else:
        pad[:len(arr)] = arr
    return np.lib.stride_tricks.as_strided(pad, shape=(len(arr) + 1, width), strides=(1, 1), writeable=False)


def _byte_masks(width: int, low: bool) -> np.ndarray:
    """(width + 1, width / 8) uint64: row ``k`` keeps the first ``k`` bytes of a row of ``width`` bytes
    (``low``), or drops them (not ``low``)."""
    keep = np.arange(width)[None, :] < np.arange(width + 1)[:, None]
    return np.ascontiguousarray(np.where(keep == low, 255, 0).astype(np.uint8)).view(np.uint64)


_MASKS = {(w, low): _byte_masks(w, low) for w in (8, 16, 24) for low in (False, True)}


def _keep_bytes(lanes: np.ndarray, count: np.ndarray, low: bool) -> None:
    """Keep, in place, the first ``count`` bytes (``low``) or all but the first ``count`` bytes (not
    ``low``) of each row of ``lanes`` ((m, W/8) uint64 view of (m, W) bytes, little-endian);
    ``count`` is clipped to 0 .. W."""
    width = 8 * lanes.shape[1]
    count = np.clip(count, 0, width)
    table = _MASKS.get((width, low))
    if table is None:       # a wide text cell: one mask a row (a table of width + 1 rows grows as width^2)
        keep = (np.arange(width)[None, :] < count[:, None]) == low
        lanes &= np.ascontiguousarray(keep.astype(np.uint8) * np.uint8(255)).view(np.uint64)
        return
    lanes &= table.take(count, axis=0)


def _all_bytes(flags: np.ndarray) -> np.ndarray:
    """Per row, whether a (m, W) bool array (W a multiple of 8) is all True."""
    lanes = flags.view(np.uint64)
    ones = _u64(0x0101010101010101)
    s = lanes[:, 0] == ones
    for j in range(1, lanes.shape[1]):
        s &= lanes[:, j] == ones
    return s


def _byte_count(flags: np.ndarray) -> np.ndarray:
    """Per row, the number of True in a (m, W) bool array (W a multiple of 8, at most 255 True)."""
    lanes = flags.view(np.uint64)
    s = lanes[:, 0].copy()
    for j in range(1, lanes.shape[1]):
        s += lanes[:, j]
    return (s * _u64(0x0101010101010101)) >> _u64(56)


def _eight_digits(lanes: np.ndarray) -> np.ndarray:
    """The number written by each uint64 of digit values 0-9 (first digit in the lowest byte)."""
    v = ((lanes & _u64(0x0F0F0F0F0F0F0F0F)) * _u64(2561)) >> _u64(8)
    v = ((v & _u64(0x00FF00FF00FF00FF)) * _u64(6553601)) >> _u64(16)
    return ((v & _u64(0x0000FFFF0000FFFF)) * _u64(42949672960001)) >> _u64(32)


def _plain_decimals(arr: np.ndarray, ending: np.ndarray, a: np.ndarray,
                    b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values of the cells ``arr[a:b]`` written as plain decimals (an optional sign, digits with at
    most one point, at most 19 characters after the sign) and ``ok``: False where a cell is anything
    else (empty, an exponent, nan, a space, too long): the caller reads those cell by cell.
    ``ending``: ``_windows(arr, 24)``.

    The digits (point dropped) form an integer mantissa ``m`` of at most 2**53 and the value is
    ``m / 10**decimals``: both are doubles exactly, so the one rounded division gives the double
    nearest the decimal, as Python's ``float`` does (``ok`` is False for a longer mantissa)."""
    m = len(a)
    if not m:
        return np.empty(0), np.ones(0, bool)
    first = np.where(a < b, arr.take(np.minimum(a, len(arr) - 1)), 0)
    neg = first == 45
    length = b - a - (neg | (first == 43))
    width = 8 * min(3, max(1, -(-int(length.max()) // 8)))
    cells = ending[b, 24 - width:]                             # right-aligned: the cell ends at column W
    digit = cells - np.uint8(48)                               # a point: 254
    _keep_bytes(digit.view(np.uint64), width - length, low=False)   # before the cell (and sign): 0
    is_digit = digit < 10
    is_point = digit == 254
    n_points = _byte_count(is_point)
    ok = _all_bytes(is_digit | is_point) & (n_points <= 1) & (length > n_points) & (length <= 19)
    # the point's column: the lowest set byte of the point flags, from the exponent of that power of 256
    lanes = is_point.view(np.uint64)
    flags = lanes[:, 0].astype(np.float64)
    for j in range(1, lanes.shape[1]):
        flags += lanes[:, j].astype(np.float64) * 2.0 ** (64 * j)
    col = ((flags.view(np.int64) >> 52) - 1023) >> 3
    decimals = np.where(n_points == 1, width - 1 - col, 0).clip(0, 19)
    digit *= is_digit
    parts = _eight_digits(digit.view(np.uint64))
    s = parts[:, 0].copy()
    for j in range(1, parts.shape[1]):
        s = s * _u64(10 ** 8) + parts[:, j]
    low = s % _POW10_U[decimals]
    # the point's column holds a 0 digit: the digits before it are one place too high
    mant = np.where(n_points == 1, (s - low) // _u64(10) + low, s)
    ok &= mant <= _u64(_EXACT)
    return mant.astype(np.float64) / _DIVISORS[decimals + 20 * neg], ok


def _numbers(arr, text, lines, num_idx, before, after) -> np.ndarray | None:
    """(n, k) values of the numeric cells of a block whose lines all have the header's cell count;
    None when it needs the careful reader. Plain decimals are read by :func:`_plain_decimals`, a few
    other cells one by one, many by numpy's reader; a bad cell: None."""
    n = len(lines)
    flat_a, flat_b = (before[:, num_idx] + 1).ravel(), after[:, num_idx].ravel()
    ending = _windows(arr, 24)
    parts = []
    for i in range(0, len(flat_a), _CELLS):
        parts.append(_plain_decimals(arr, ending, flat_a[i:i + _CELLS], flat_b[i:i + _CELLS]))
        if i == 0 and np.count_nonzero(~parts[0][1]) > 16 + len(parts[0][1]) // 1000:
            break                                         # another notation: stop here
    values, ok = np.concatenate([v for v, _ in parts]), np.concatenate([o for _, o in parts])
    odd = np.flatnonzero(~ok)
    if len(values) < len(flat_a) or len(odd) > 16 + len(values) // 1000:
        # many cells in another notation (exponents): numpy's reader, or the careful one (numpy takes a no-break
        # space or another Unicode space around a number: a block that is not ASCII goes to the careful reader)
        if not text.isascii():
            return None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                numbers = np.loadtxt(io.StringIO(text), dtype=float, usecols=num_idx, delimiter=",", comments=None,
                                     quotechar=None, ndmin=2, encoding=None)
        except ValueError:
            return None
        return numbers if numbers.shape[0] == n else None
    for i in odd.tolist():
        v = parse_number(arr[flat_a[i]:flat_b[i]].tobytes().decode("utf-8"))
        if v is None:
            return None                                   # the careful reader: its located error
        values[i] = v
    return values.reshape(n, len(num_idx))


def _regular_layout(arr: np.ndarray, body: bytes, k: int):
    """The common case in one pass: every line ends with a newline, holds ``k`` commas and is not
    blank, no carriage return. (kept line indices, before, after) as :func:`_lines_layout`, or None."""
    if not body.endswith(b"\n") or b"\r" in body:
        return None
    seps = np.flatnonzero((arr == 44) | (arr == 10))
    if len(seps) % (k + 1):
        return None
    after = seps.reshape(-1, k + 1)
    ends = after[:, -1]
    want = np.full(k + 1, 44, np.uint8)                   # k commas, then the newline
    want[-1] = 10
    if not np.all(arr[after] == want) or ends[0] == 0 or np.any(ends[1:] - ends[:-1] == 1):
        return None                                       # a wrong cell count, a blank line
    n = len(ends)
    flat = np.empty(len(seps) + 1, np.int64)
    flat[0] = -1
    flat[1:] = seps
    return np.arange(n), flat[:-1].reshape(n, k + 1), after


def _lines_layout(arr: np.ndarray, k: int):
    """(kept line indices, before, after) of the non-empty lines (a final line may lack its newline;
    a carriage return before a newline is dropped): cell ``c`` of row ``i`` is
    ``arr[before[i, c] + 1:after[i, c]]``. None unless every kept line has exactly ``k`` commas."""
    ends = np.flatnonzero(arr == 10)
    if len(arr) and arr[-1] != 10:
        ends = np.append(ends, len(arr))
    starts = np.empty_like(ends)
    starts[:1] = 0
    starts[1:] = ends[:-1] + 1
    lengths = ends - starts
    cr = np.zeros(len(ends), bool)
    has = lengths > 0
    cr[has] = arr[ends[has] - 1] == 13
    lengths = lengths - cr
    keep = np.flatnonzero(lengths > 0)
    starts, stops = starts[keep], starts[keep] + lengths[keep]
    n = len(keep)
    # every kept line has exactly k commas: the commas, k to a line in file order, all lie inside
    # their line (a blank-looking line or a wrong cell count: the careful reader)
    commas = np.flatnonzero(arr == 44)
    if len(commas) != n * k:
        return None
    commas = commas.reshape(n, k)
    if k and n and (np.any(commas[:, 0] <= starts - 1) or np.any(commas[:, -1] >= stops)):
        return None
    return keep, np.column_stack([starts - 1, commas]), np.column_stack([commas, stops])


def _fast_block(body: bytes, text: str, path: str, first_line: int, header: list[str], num_idx,
                txt_idx) -> CsvBlock | None:
    """The vectorised reader on a block of whole lines (``body``, decoded: ``text``), or None when the
    block needs the careful reader."""
    if b'"' in body or not np.little_endian:          # (a NUL byte was refused by decode_text)
        return None
    arr = np.frombuffer(body, np.uint8)
    k = len(header) - 1
    layout = _regular_layout(arr, body, k)
    if layout is None:
        layout = _lines_layout(arr, k)
        if layout is None:
            return None
    keep, before, after = layout
    n = len(keep)
    lines = first_line + keep
    if not n:
        return CsvBlock(lines, np.empty((0, len(num_idx))), np.empty((0, len(txt_idx)), dtype=str))
    if num_idx:
        numbers = _numbers(arr, text, lines, num_idx, before, after)
        if numbers is None:
            return None
    else:
        numbers = np.empty((n, 0))
    texts = np.empty((n, len(txt_idx)), dtype=object)
    for j, c in enumerate(txt_idx):
        texts[:, j] = _cells_text(arr, before[:, c] + 1, after[:, c])
    return CsvBlock(lines, numbers, texts)


def _cells_text(arr: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Object array of the stripped text of cells ``arr[a:b]``; equal cells share one string (equal
    neighbours, a measurement's rows, are decoded once)."""
    width = -(-int((b - a).max()) // 8) * 8 if len(a) else 0
    if width == 0:
        return np.full(len(a), "", dtype=object)
    if width * len(a) > 4 * len(arr) + (1 << 20):   # a few cells much wider than the rest: the (n, width)
        return np.array([arr[x:y].tobytes().decode("utf-8").strip()   # matrix would outgrow the file itself
                         for x, y in zip(a.tolist(), b.tolist(), strict=True)] + [None], dtype=object)[:-1]
    cells = _windows(arr, width, before=False)[a]
    lanes = cells.view(np.uint64)
    _keep_bytes(lanes, b - a, low=True)
    new = np.zeros(len(a), bool)
    new[0] = True
    for j in range(lanes.shape[1]):
        new[1:] |= lanes[1:, j] != lanes[:-1, j]
    uniq, inv = np.unique(cells[new].view(f"S{width}").ravel(), return_inverse=True)
    decoded = np.array([u.decode("utf-8").strip() for u in uniq.tolist()], dtype=object)
    return decoded[inv.ravel()[np.cumsum(new) - 1]]


def _find_header(data: bytes, path, line_no: int):
    """The header in ``data`` (whole lines from line ``line_no``): the first non-blank line.
    ``(names, line, end)``: stripped names, its line and the offset after it; None if ``data`` holds
    only blank lines."""
    pos = 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl
        raw = decode_text(data[pos:end], path, line_no)
        if raw.strip():
            recs = csv_records(raw, str(path), line_no)
            if recs:
                return [h.strip() for h in recs[0][1]], line_no, end + 1
        line_no += 1
        pos = end + 1
    return None


def csv_spans(path: str | Path, parts: int, min_bytes: int | None = None) -> tuple | None:
    """Split a large CSV file into ``parts`` byte ranges of whole lines after its header, for reading
    in parallel with :func:`iter_csv_blocks` (``span``, ``known_header``).
    ``((header_line, names), [(start, stop), ...])``: the first range starts at 0 (it holds the
    header), the others at a line start after it. None for a file under ``min_bytes``, not a regular
    file, or whose header is not in its first MiB (default ``min_bytes``: :data:`PARALLEL_BYTES`): the
    caller reads it whole (with its located errors)."""
    try:
        st = os.stat(path)
        if parts < 2 or st.st_size < (PARALLEL_BYTES if min_bytes is None else min_bytes) \
                or not stat.S_ISREG(st.st_mode):
            return None
        size = st.st_size
        with open(path, "rb") as fh:
            head = fh.read(1 << 20)
            bom = 3 if head.startswith(b"\xef\xbb\xbf") else 0
            cut = head.rfind(b"\n") + 1
            found = _find_header(head[bom:cut], path, 1) if cut > bom else None
            if found is None:
                return None
            names, line, end = found
            bounds = [0]
            for k in range(1, parts):
                fh.seek(max(bom + end, size * k // parts) - 1)
                tail = fh.read(1 << 16)
                nl = tail.find(b"\n")
                if nl < 0:
                    return None
                bounds.append(fh.tell() - len(tail) + nl + 1)
    except (OSError, InputError):
        return None                                       # the serial reader says what is wrong
    bounds.append(size)
    if any(b >= c for b, c in zip(bounds[:-1], bounds[1:], strict=True)):
        return None
    return (line, names), list(zip(bounds[:-1], bounds[1:], strict=True))


def iter_csv_blocks(path: str | Path, what: str, header_check, block_bytes: int = BLOCK_BYTES,
                    data: bytes | None = None, span: tuple[int, int] | None = None,
                    known_header: tuple[int, list[str]] | None = None):
    """Read a CSV file (or ``data``, its bytes, with ``path`` only named in messages) in blocks of
    whole lines.

    ``header_check(header: list[str], header_line: int) -> (num_idx, txt_idx)`` validates the header
    (stripped names) and says which columns are numbers and which are kept as text. Yields
    ``(header_line, header, CsvBlock)`` (the block possibly empty). Raises InputError for an empty
    file or a file with no header; the caller checks that rows came.

    ``span=(start, stop)``: only the bytes ``start:stop`` of the file (whole lines, from
    :func:`csv_spans`); a span that starts after the header takes it as ``known_header=(line,
    names)`` and numbers its lines by counting the newlines before ``start``.
    """
    start, stop = span if span is not None else (0, None)
    if data is not None:
        fh = io.BytesIO(data)
    else:
        fh = open_input(path, what)
    def read(limit: int | None) -> bytes:
        """The next block, at most up to the offset ``limit``."""
        try:
            want = block_bytes if limit is None else min(block_bytes, limit - fh.tell())
            return fh.read(want) if want > 0 else b""
        except OSError as exc:
            raise InputError(f"cannot read {what}: {exc.strerror}", path) from None

    with fh:
        carry, line_no, header, first = b"", 1, None, True
        num_idx = txt_idx = None
        if start:
            while block := read(start):
                line_no += block.count(b"\n")
            header_line, header = known_header  # type: ignore[misc]
            num_idx, txt_idx = header_check(header, header_line)
            first = False
        while True:
            block = read(stop)
            eof = not block
            data = carry + block
            if first and data.startswith(b"\xef\xbb\xbf"):
                data = data[3:]
            if not eof:
                cut = data.rfind(b"\n") + 1
                if cut == 0:
                    carry, first = data, False if data else first
                    continue
                data, carry = data[:cut], data[cut:]
            first = False
            if header is None:
                found = _find_header(data, path, line_no)
                if found is None:
                    if eof:
                        raise InputError("the file is empty (expected a header line and data)", path, 1)
                    line_no += data.count(b"\n")
                    continue
                header, header_line, pos = found
                num_idx, txt_idx = header_check(header, header_line)
                line_no = header_line + 1
                data = data[pos:]
            if data:
                text = decode_text(data, path, line_no)     # located error for a bad byte (a NUL, a lone CR)
                blk = _fast_block(data, text, str(path), line_no, header, num_idx, txt_idx)
                if blk is None:
                    blk = _slow_block(text, str(path), line_no, header, num_idx, txt_idx)
                line_no += data.count(b"\n")
                yield header_line, header, blk
            if eof:
                break


# ---------------------------------------------------------------------------------------------
# writing

_FIXED = re.compile(r"%\.(\d)f")


def _fixed_chars(v: np.ndarray, decimals: int) -> np.ndarray | None:
    """(W, n) uint8 matrix, one row per character position, of the ``%.{decimals}f`` texts of ``v``
    (right-aligned, 0 where no character); None when the fast path cannot be exact (a non-finite
    value, more than 15 digits, many values within an ulp of a half)."""
    v = np.asarray(v, dtype=float)
    n = len(v)
    if not np.all(np.isfinite(v)) or (n and np.max(np.abs(v)) > 9e15 / 10.0 ** decimals):
        return None
    scale = 10 ** decimals
    prod = np.abs(v) * scale
    scaled = (prod + 0.5).astype(np.int64)              # round half up, halves fixed below
    # the float product can round a value that lies within an ulp of a half the wrong way: those few
    # are rounded exactly (half to even, as Python's % does) from the double's exact decimal value
    near = np.flatnonzero(np.abs(np.abs(prod - scaled) - 0.5) <= prod * 4.5e-16 + 1e-300)
    if len(near) > 64 + n // 100:
        return None                                       # huge values: Python's formatting
    for i in near:
        scaled[i] = int((Decimal(abs(float(v[i]))) * scale).quantize(Decimal(1), ROUND_HALF_EVEN))
    ndig = max(len(str(int(scaled.max()))) if n else 1, decimals + 1)
    point = 1 if decimals else 0
    m = np.empty((1 + ndig + point, n), np.uint8)       # sign, digits, point, decimals
    x = scaled
    top = np.full(n, ndig - decimals - 1, np.int64)      # row of a sign: just before the first digit
    for k in range(ndig):                                 # the k-th digit from the right
        if k % 4 == 0:                                    # four digits at a time in uint16: cheaper
            if k + 4 < ndig:
                q = x // 10000
                group = (x - q * 10000).astype(np.uint16)
                x = q
            else:
                group = x.astype(np.uint16)
        row = ndig - k if k >= decimals else ndig + 1 - k
        q16 = group // 10                                 # (np.divmod is many times slower)
        d = (group - q16 * 10).astype(np.uint8) + 48
        group = q16
        if k > decimals:                                  # a leading zero of the integer part: none
            shown = scaled >= 10 ** k
            m[row] = d * shown
            top -= shown
        else:
            m[row] = d
    if point:
        m[ndig - decimals + 1] = 46
    m[0] = 0
    rows = np.flatnonzero((v < 0) & (scaled != 0))
    m[top[rows], rows] = 45
    return m


def _text_chars(values) -> np.ndarray | None:
    """(W, n) uint8 matrix of the CSV cells of text values (quoted where needed), 0 where no
    character, or None when a few cells are much wider than the rest (the row-by-row writer then). Equal
    neighbours (a measurement's rows) are encoded once."""
    vals = np.asarray(values, dtype=object)
    n = len(vals)
    new = np.ones(n, bool)
    if n > 1:
        new[1:] = vals[1:] != vals[:-1]
    uniq, inv = np.unique(vals[new].astype(str), return_inverse=True)
    inv = inv.ravel()[np.cumsum(new) - 1]

    def cell(s: str) -> bytes:
        if any(c in s for c in ',"\n\r') or s != s.strip():
            s = '"' + s.replace('"', '""') + '"'
        return s.encode("utf-8")
    enc = [cell(u) for u in uniq.tolist()]
    width = max([len(e) for e in enc] + [1])
    if width * n > 4 * int(np.array([len(e) for e in enc] + [0])[inv].sum()) + (1 << 20):
        return None         # a few cells much wider than the rest: the (width, n) matrix would outgrow the text
    table = np.zeros((width, len(enc)), np.uint8)
    for i, e in enumerate(enc):
        table[: len(e), i] = np.frombuffer(e, np.uint8)
    return table[:, inv]


def _column_chars(c: np.ndarray, fmt: str) -> np.ndarray | None:
    if c.dtype.kind == "b":
        c = c.astype(np.int64)
    if c.dtype.kind in "iu":
        if len(c) and np.max(np.abs(c)) > 9e15:
            return None
        return _fixed_chars(c.astype(float), 0)
    if c.dtype.kind == "f":
        m = _FIXED.fullmatch(fmt)
        return None if m is None else _fixed_chars(c, int(m.group(1)))
    return _text_chars(c)


def _rows_text(mats: list[np.ndarray]) -> bytes:
    """The CSV rows of the (W, n) character matrices of the columns (separators added), transposed to
    text order; the empty positions (0) are dropped."""
    n = mats[0].shape[1]
    parts = []
    for m in mats:
        parts += [m, np.full((1, n), 44, np.uint8)]
    parts[-1] = np.full((1, n), 10, np.uint8)
    text = np.ascontiguousarray(np.concatenate(parts).T).ravel()
    return text[text != 0].tobytes()


def _slow_rows(columns: list[np.ndarray], fmts: list[str]) -> bytes:
    def cells(c: np.ndarray, fmt: str) -> list[str]:
        if c.dtype.kind in "iub":
            return [str(int(v)) for v in c]
        if c.dtype.kind == "f":
            return [fmt % v for v in c]
        return [str(v) for v in c]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerows(zip(*(cells(c, f) for c, f in zip(columns, fmts, strict=True)), strict=True))
    return buf.getvalue().encode("utf-8")


def format_row(values: dict, fmt="%.9g") -> str:
    """The text of the one CSV row of ``{name: value}`` that :func:`format_csv` writes for one-row
    columns of these values (same formats, quoting and zeros), without its arrays: for a file written a
    row at a time (a live session's ``tips.csv`` must equal ``aacmm tip``'s output byte for byte)."""
    names = list(values)
    fmts = [fmt.get(k, "%.9g") if isinstance(fmt, dict) else fmt for k in names]
    vals = [values[k] for k in names]

    def fast(v, f) -> bool:           # the column would take format_csv's vectorised path
        if isinstance(v, (bool, int, np.integer, np.bool_)):
            return abs(int(v)) <= 9e15
        if isinstance(v, (float, np.floating)):
            m = _FIXED.fullmatch(f)
            return m is not None and math.isfinite(v) and abs(float(v)) * 10.0 ** int(m.group(1)) <= 9e15
        return True
    if all(fast(v, f) for v, f in zip(vals, fmts, strict=True)):
        cells = []
        for v, f in zip(vals, fmts, strict=True):
            if isinstance(v, (bool, int, np.integer, np.bool_)):
                cells.append(str(int(v)))
            elif isinstance(v, (float, np.floating)):
                t = f % float(v)
                cells.append(t[1:] if t.startswith("-") and not t.strip("-0.") else t)   # no "-0.000"
            else:
                t = str(v)
                cells.append('"' + t.replace('"', '""') + '"' if any(c in t for c in ',"\n\r') or t != t.strip()
                             else t)
        return ",".join(cells) + "\n"
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(
        [str(int(v)) if isinstance(v, (bool, int, np.integer, np.bool_)) else
         f % v if isinstance(v, (float, np.floating)) else str(v) for v, f in zip(vals, fmts, strict=True)])
    return buf.getvalue()


def format_csv(columns: dict, fmt="%.9g", header: bool = True, chunk: int = 16_384) -> bytes:
    """CSV bytes of ``{name: 1-D array}``. ``fmt``: one ``%`` format for the float columns or a dict
    ``{name: format}`` (default ``%.9g`` for names it does not list). Fixed formats (``%.6f``), integer
    and text columns are formatted by vectorised code."""
    names = list(columns)
    lengths = {len(v) for v in columns.values()}
    if len(lengths) > 1:
        raise ValueError(f"columns of different lengths: {lengths}")
    n = lengths.pop() if lengths else 0
    fmts = [fmt.get(k, "%.9g") if isinstance(fmt, dict) else fmt for k in names]
    out = []
    if header:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow(names)
        out.append(buf.getvalue().encode("utf-8"))
    for a in range(0, n, chunk):
        cols = [np.asarray(columns[k])[a:a + chunk] for k in names]
        mats = [_column_chars(c, f) for c, f in zip(cols, fmts, strict=True)]
        if any(m is None for m in mats):
            out.append(_slow_rows(cols, fmts))
            continue
        out.append(_rows_text(mats))
    return b"".join(out)


def label_rows(labels) -> dict[str, np.ndarray]:
    """``{label: its rows (file order)}`` of the (N,) ``labels`` (text), in order of first appearance, in one sort
    (not one pass over every row a label)."""
    ids, first, inverse = np.unique(np.asarray(labels), return_index=True, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    split = np.split(order, np.cumsum(np.bincount(inverse.ravel(), minlength=len(ids)))[:-1])
    return {str(ids[k]): split[k] for k in np.argsort(first, kind="stable")}
