"""Fast, strict CSV reading and writing for large files (millions of rows).

Reading: the file is read in blocks of whole lines; each block is parsed by numpy's C reader
(``np.loadtxt``) after a vectorised check of the cell count of every line. Anything the fast path
does not accept exactly (a quoted cell, a bad number, a wrong cell count, a blank-looking line)
sends that block to the cell-by-cell reader, which either parses it the same way or raises the
located :class:`InputError` (file, line, column). Both paths accept the same numbers: ASCII
decimals with an optional exponent (``12.5``, ``-3e-4``) and ``nan``/``inf`` (callers refuse
non-finite values with their location); never ``4_5`` (Python's ``float`` would read 45), hex,
or non-ASCII digits.

Writing: fixed-decimal columns (``%.6f``) are formatted by integer arithmetic on numpy arrays,
then the used characters of the byte matrix are kept, row by row; other formats fall back to
Python's ``%`` formatting.
"""
from __future__ import annotations

import csv
from decimal import ROUND_HALF_EVEN, Decimal
import io
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._errors import InputError

__all__ = ["parse_number", "csv_records", "CsvBlock", "iter_csv_blocks", "format_csv"]

_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:nan|inf|infinity)",
                     re.IGNORECASE)
BLOCK_BYTES = 1 << 22          # 4 MiB (about 37 000 points rows): small temporaries, few page faults


def parse_number(cell: str) -> float | None:
    """The number in a (stripped) cell, or None if it is not one (see the module doc)."""
    return float(cell) if _NUMBER.fullmatch(cell) else None


def csv_records(text: str, path: str, first_line: int = 1) -> list[tuple[int, list[str]]]:
    """Non-blank CSV records with their physical line; a record may not span lines."""
    out = []
    for no, line in enumerate(text.splitlines(), start=first_line):
        if not line.strip():
            continue
        try:
            rec = next(csv.reader([line], strict=True))
        except csv.Error as exc:
            raise InputError(f"not valid CSV: {exc}", path, no) from None
        if any(c.strip() for c in rec):
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
            cell = r[c].strip()
            v = parse_number(cell)
            if v is None:
                raise _empty_cell_error(cell, path, no, header[c])
            numbers[i, k] = v
        for k, c in enumerate(txt_idx):
            texts[i, k] = r[c].strip()
    return CsvBlock(np.array([no for no, _ in recs], dtype=np.int64), numbers, texts)


def _fast_block(body: bytes, text: str, path: str, first_line: int, header: list[str], num_idx,
                txt_idx) -> CsvBlock | None:
    """numpy's reader on a block of whole lines (``body``, decoded: ``text``), or None when the block
    needs the careful reader."""
    if b'"' in body:
        return None
    arr = np.frombuffer(body, np.uint8)
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
    n, k = len(keep), len(header) - 1
    # every kept line has exactly k commas: the commas, k to a line in file order, all lie inside
    # their line (a blank-looking line or a wrong cell count: the careful reader)
    commas = np.flatnonzero(arr == 44)
    if len(commas) != n * k:
        return None
    commas = commas.reshape(n, k)
    if k and n and (np.any(commas[:, 0] <= starts - 1) or np.any(commas[:, -1] >= stops)):
        return None
    lines = first_line + keep
    if not n:
        return CsvBlock(lines, np.empty((0, len(num_idx))), np.empty((0, len(txt_idx)), dtype=str))
    kw = dict(delimiter=",", comments=None, quotechar=None, ndmin=2, encoding=None)
    if num_idx:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                numbers = np.loadtxt(io.StringIO(text), dtype=float, usecols=num_idx, **kw)
        except ValueError:
            return None
        if numbers.shape[0] != n:
            return None
    else:
        numbers = np.empty((n, 0))
    texts = np.empty((n, len(txt_idx)), dtype=object)
    for j, c in enumerate(txt_idx):                       # cell c: between comma c - 1 and comma c
        a = starts if c == 0 else commas[:, c - 1] + 1
        texts[:, j] = _cells_text(arr, a, stops if c == k else commas[:, c])
    return CsvBlock(lines, numbers, texts)


def _cells_text(arr: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Object array of the stripped text of cells ``arr[a:b]``; equal cells share one string (equal
    neighbours, a measurement's rows, are decoded once)."""
    width = int((b - a).max()) if len(a) else 0
    if width == 0:
        return np.full(len(a), "", dtype=object)
    cells = np.zeros((len(a), width), np.uint8)
    for p in range(width):
        cells[:, p] = np.where(a + p < b, arr[np.minimum(a + p, len(arr) - 1)], 0)
    new = np.ones(len(a), bool)
    new[1:] = np.any(cells[1:] != cells[:-1], axis=1)
    uniq, inv = np.unique(cells[new].view(f"S{width}").ravel(), return_inverse=True)
    decoded = np.array([u.decode("utf-8").strip() for u in uniq.tolist()], dtype=object)
    return decoded[inv.ravel()[np.cumsum(new) - 1]]


def _decode(data: bytes, path, first_line: int) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError("not UTF-8 text", path, first_line + data[: exc.start].count(b"\n")) from None


def iter_csv_blocks(path: str | Path, what: str, header_check, block_bytes: int = BLOCK_BYTES,
                    data: bytes | None = None):
    """Read a CSV file (or ``data``, its bytes, with ``path`` only named in messages) in blocks of
    whole lines.

    ``header_check(header: list[str], header_line: int) -> (num_idx, txt_idx)`` validates the header
    (stripped names) and says which columns are numbers and which are kept as text. Yields
    :class:`CsvBlock` (possibly empty). Raises InputError for an empty file or a file with no
    header; the caller checks that rows came.
    """
    if data is not None:
        fh = io.BytesIO(data)
    else:
        try:
            fh = open(path, "rb")
        except OSError as exc:
            raise InputError(f"cannot read {what}: {exc.strerror}", path) from None
    with fh:
        carry, line_no, header, first = b"", 1, None, True
        num_idx = txt_idx = None
        while True:
            try:
                block = fh.read(block_bytes)
            except OSError as exc:
                raise InputError(f"cannot read {what}: {exc.strerror}", path) from None
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
                # the header: the first non-blank line
                pos = 0
                while pos < len(data):
                    nl = data.find(b"\n", pos)
                    end = len(data) if nl < 0 else nl
                    raw = _decode(data[pos:end], path, line_no)
                    if raw.strip():
                        recs = csv_records(raw, str(path), line_no)
                        if recs:
                            header = [h.strip() for h in recs[0][1]]
                            num_idx, txt_idx = header_check(header, line_no)
                            header_line = line_no
                            line_no += 1
                            pos = end + 1
                            break
                    line_no += 1
                    pos = end + 1
                data = data[pos:]
                if header is None:
                    if eof:
                        raise InputError("the file is empty (expected a header line and data)", path, 1)
                    continue
            if data:
                text = _decode(data, path, line_no)     # located error for a bad byte
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
    if not np.all(np.isfinite(v)) or (n and np.max(np.abs(v)) * 10.0 ** decimals > 9e15):
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
        row = ndig - k if k >= decimals else ndig + 1 - k
        q = x // 10                                       # (np.divmod is many times slower)
        d = (x - q * 10).astype(np.uint8) + 48
        if k > decimals:                                  # a leading zero of the integer part: none
            shown = x > 0
            m[row] = d * shown
            top -= shown
        else:
            m[row] = d
        x = q
    if point:
        m[ndig - decimals + 1] = 46
    m[0] = 0
    rows = np.flatnonzero((v < 0) & (scaled != 0))
    m[top[rows], rows] = 45
    return m


def _text_chars(values) -> np.ndarray:
    """(W, n) uint8 matrix of the CSV cells of text values (quoted where needed), 0 where no
    character. Equal neighbours (a measurement's rows) are encoded once."""
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
    """The CSV rows of the (W, n) character matrices of the columns: one row per character position
    (each written contiguously), packed eight positions to a uint64 so that the transposition to
    text order moves words, not bytes; the empty positions (0) are dropped."""
    n = mats[0].shape[1]
    sep = np.full((1, n), 44, np.uint8)
    parts = []
    for m in mats:
        parts += [m, sep]
    parts[-1] = np.full((1, n), 10, np.uint8)
    width = sum(len(p) for p in parts)
    chars = np.zeros((-(-width // 8) * 8, n), np.uint8)
    np.concatenate(parts, out=chars[:width])
    packed = np.zeros((len(chars) // 8, n), np.uint64)
    for b in range(8):       # byte b of each word: position 8 r + b (the words are read back as bytes)
        word = chars[b::8].astype(np.uint64)
        packed |= word << np.uint64(8 * b) if np.little_endian else word << np.uint64(56 - 8 * b)
    text = np.ascontiguousarray(packed.T).view(np.uint8).ravel()
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
    w.writerows(zip(*(cells(c, f) for c, f in zip(columns, fmts))))
    return buf.getvalue().encode("utf-8")


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
        mats = [_column_chars(c, f) for c, f in zip(cols, fmts)]
        if any(m is None for m in mats):
            out.append(_slow_rows(cols, fmts))
            continue
        out.append(_rows_text(mats))
    return b"".join(out)
