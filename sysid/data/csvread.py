"""Strict, vectorised CSV reading for :func:`sysid.data.io.read_record`: a row that breaks a rule is refused with its
line number, never dropped or altered.

The rules a CSV file must follow are in ``docs/data-files.md``; in short:

- UTF-8 text (a byte-order mark is accepted), line endings LF, CRLF or CR.
- Delimiter ``,``, ``;``, tab or runs of spaces, detected from the first lines: the one that splits every
  sampled line into the same number (≥ 2) of cells. Decimal mark ``.``; a decimal comma (``-0,62``) is
  accepted when the delimiter is ``;``, tab or spaces. A file whose lines split differently is refused.
- Optional header row (names, quotes allowed: ``"V1","V2"``). A file without one has columns ``0, 1, 2 ...``;
  an ``np.savetxt`` header (``# t,u,y`` as the last comment line before numeric rows) names the columns.
- Lines whose first character is ``#`` are comments, anywhere. Blank lines are accepted only before the
  header and at the end of the file; a blank line between data rows is refused (never dropped silently).
- Every data row has exactly as many cells as the header; a row with more or fewer is refused, naming the
  line. The selected columns must hold numbers (or be empty / ``nan`` for missing samples); a cell that is not
  a number is refused with its line and column. Columns that are not selected may hold anything.
- Time column (first of, case-insensitive): ``t``, ``time``, ``t_s``, ``time_s`` (seconds), ``t_ms``,
  ``time_ms`` (milliseconds), ``t_us``, ``time_us`` (microseconds): it gives the sampling rate.

Parsing of the numbers is done by :func:`pandas.read_csv` (C engine) on the selected columns; the structural
checks (cells per line, blank lines, comments) are vectorised with numpy over the file's bytes, so the whole
read stays within about 1.5x of ``pandas.read_csv`` alone (``tests/perf/test_csv_read.py``).
"""

from __future__ import annotations

import csv
import io
import mmap
import re
from pathlib import Path

import numpy as np

from sysid.errors import DataError

__all__ = ["CsvTable", "parse_csv", "TIME_COLUMNS"]

#: time-column names (lower case) and the factor to seconds
TIME_COLUMNS = {
    "t": 1.0,
    "time": 1.0,
    "t_s": 1.0,
    "time_s": 1.0,
    "t_ms": 1e-3,
    "time_ms": 1e-3,
    "t_us": 1e-6,
    "time_us": 1e-6,
}
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf|infinity)$", re.IGNORECASE)
_NUM_COMMA = re.compile(r"^[+-]?(\d+,?\d*|,\d+)([eE][+-]?\d+)?$")
_SAMPLE = 200  # lines used to detect the delimiter and decimal mark


class CsvTable:
    """Header and column access of a parsed CSV file; columns are parsed on demand."""

    def __init__(
        self,
        src: str,
        header: list[str],
        body: bytes,
        line_no: np.ndarray,
        delimiter: str,
        decimal: str,
        has_header: bool,
        skip: int = 0,
        verify_width: bool = False,
    ):
        self.src, self.header, self.body, self.line_no, self.skip = src, header, body, line_no, skip
        self.nrows: int | None = None  # set when lines that are not data follow the data block
        self.verify_width = verify_width  # parse every column once, so that pandas refuses longer rows
        self.delimiter, self.decimal, self.has_header = delimiter, decimal, has_header
        self.index = {name: i for i, name in enumerate(header) if name != ""}
        self._cache: dict[int, np.ndarray] = {}

    def __len__(self) -> int:
        return int(self.line_no.size)

    def prefetch(self, names: list[str]) -> None:
        """Parse all these columns (those present) in one pass, so later :meth:`columns` calls are free."""
        todo = sorted(
            {self.index[n] for n in names if n in self.index and self.header.count(n) == 1} - set(self._cache)
        )
        if self.verify_width:
            self._parse(list(range(len(self.header))), keep=todo)
            self.verify_width = False
        elif todo:
            self._parse(todo)

    def columns(self, names: list[str]) -> list[np.ndarray]:
        """Parse the named columns (one pandas pass for all of them) as float64 arrays."""
        for n in names:
            if self.header.count(n) > 1:
                raise DataError(
                    f"{self.src}: column {n!r} appears {self.header.count(n)} times in the header; rename the copies"
                )
        idx = [self.index[n] for n in names]
        todo = sorted({i for i in idx if i not in self._cache})
        if todo:
            self._parse(todo)
        return [self._cache[i] for i in idx]

    def _parse(self, cols: list[int], keep: list[int] | None = None) -> None:
        import pandas as pd

        sep = r"\s+" if self.delimiter == " " else self.delimiter
        try:
            data = io.BytesIO(self.body) if isinstance(self.body, bytes) else self.body
            df = pd.read_csv(
                data,
                sep=sep,
                decimal=self.decimal,
                header=None,
                usecols=None if self.verify_width else cols,
                skiprows=self.skip,
                nrows=self.nrows,
                engine="c",
                quotechar='"',
            )
        except pd.errors.ParserError:
            if self.verify_width:  # a row longer than the header: the full check names it
                parse_csv(Path(self.src), self.src, fast=False)
            raise DataError(f"{self.src}: cannot parse the data rows (rows of unequal length)") from None
        except Exception as exc:  # structural problems were found before; this is a last guard
            raise DataError(
                f"{self.src}: cannot parse the data rows ({type(exc).__name__}: "
                f"{str(exc).splitlines()[-1] if str(exc) else ''})"
            ) from None
        if len(df) != len(self):
            raise DataError(f"{self.src}: {len(df)} data rows parsed, {len(self)} expected; check quotes in the file")
        if self.verify_width and len(df.columns) != len(self.header):
            parse_csv(Path(self.src), self.src, fast=False)
        for c in cols if keep is None else keep:
            s = df[c]
            if s.dtype.kind not in "fiu":
                num = pd.to_numeric(s, errors="coerce")
                bad = np.flatnonzero(num.isna().to_numpy() & s.notna().to_numpy())
                if bad.size:
                    k = int(bad[0])
                    name = self.header[c]
                    raise DataError(
                        f"{self.src}: column {name!r} row {k + 1 + self.has_header} is not a number: "
                        f"{s.iloc[k]!r} (line {int(self.line_no[k])}, column {c + 1})"
                        + (
                            "; decimal commas need ';', tab or space as delimiter"
                            if self.decimal == "." and re.match(r"^-?\d+,\d+$", str(s.iloc[k]))
                            else ""
                        )
                    )
                s = num
            self._cache[c] = s.to_numpy(dtype=np.float64, na_value=np.nan)


def _decode(raw: bytes, src: str) -> bytes:
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in raw[:65536]:
        raise DataError(f"{src}: not a UTF-8 text CSV file (UTF-16 or binary); save it as UTF-8")
    if not raw.isascii():
        try:
            raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise DataError(f"{src}: not a UTF-8 text CSV file (byte {exc.start} does not decode)") from None
    if b"\r" in raw:
        raw = raw.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return raw


def _load(p: Path, src: str):
    """The file's bytes (a read-only memory map when the file is plain UTF-8 with LF line ends, so nothing
    is copied and pandas reads the file itself) and the source pandas parses (path or bytes)."""
    with open(p, "rb") as fh:
        try:
            mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        except (ValueError, OSError):
            mm = None
    if (
        mm is not None
        and not mm[:3].startswith((b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff"))
        and mm.find(b"\r") < 0
        and mm.find(b"\x00") < 0
        and np.frombuffer(mm, dtype=np.uint8).max() < 128
    ):
        return mm, str(p)
    raw = _decode(mm[:] if mm is not None else p.read_bytes(), src)
    return raw, raw


def _split_cells(line: str, delim: str) -> list[str]:
    if delim == " ":
        return [c.strip('"') for c in line.split()]
    return [c.strip() for c in next(csv.reader([line], delimiter=delim, quotechar='"'))]


def _mode(values: list[int]) -> tuple[int, float]:
    """Most common value and the fraction of ``values`` equal to it."""
    vals, cnt = np.unique(np.asarray(values), return_counts=True)
    k = int(np.argmax(cnt))
    return int(vals[k]), float(cnt[k]) / len(values)


def _detect(lines: list[str], header_line: str | None, src: str, first_line: int) -> tuple[str, str]:
    """Delimiter and decimal mark from sample data lines (and the header): the first of tab, ';', ','
    that splits most lines (and the header, when there is one) into the same number (>= 2) of cells, else
    runs of spaces. Rows that then split differently are refused later, naming the line."""
    delim = None
    for d in ("\t", ";", ","):
        m, frac = _mode([ln.count(d) for ln in lines])
        if m >= 1 and frac >= 0.5 and (header_line is None or len(_split_cells(header_line, d)) == m + 1):
            delim = d
            break
    if delim is None and header_line is not None:  # rows disagree: the header's delimiter, rows checked later
        delim = next((d for d in ("\t", ";", ",") if len(_split_cells(header_line, d)) >= 2), None)
    if delim is None:
        m, frac = _mode([len(ln.split()) for ln in lines])
        if m >= 2 and frac >= 0.5:
            delim = " "
        elif m == 1 and frac == 1.0 and not any(c in ln for ln in lines for c in ",;\t"):
            delim = ","  # one column
        else:
            raise DataError(
                f"{src}: cannot tell the delimiter: lines {first_line}.. split into different numbers "
                "of cells by ',', ';', tab and spaces alike; see docs/data-files.md"
            )
    decimal = "."
    if delim != ",":
        cells = [c for ln in lines for c in _split_cells(ln, delim)]
        comma = any(_NUM_COMMA.match(c) and "," in c for c in cells)
        dot = any("." in c and _NUM.match(c) for c in cells)
        if comma and dot:
            raise DataError(f"{src}: both '.' and ',' used as decimal mark in lines {first_line}..; use one")
        if comma:
            decimal = ","
    return delim, decimal


def _head_layout(raw: bytes, src: str) -> tuple[str, str, bool, list[str], int]:
    """Delimiter, decimal mark, header flag, header names and the index of the first data line, from the
    first lines of the file."""
    head = raw[: 1 << 18].split(b"\n")
    if len(raw) > 1 << 18:
        head = head[:-1]  # the last piece may be a partial line
    lines = [ln.decode("utf-8", errors="replace") for ln in head]
    content = [i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    if not content:
        raise DataError(f"{src}: file has no rows (only blank or # comment lines)")
    h = content[0]
    first = lines[h]
    sample = [lines[i] for i in content[1 : _SAMPLE + 1]]
    try:
        probe = _detect(sample[:20], None, src, h + 2)[0] if sample else ","
    except DataError:
        probe = ","
    cells0 = _split_cells(first, probe)
    if all(c == "" or _NUM.match(c) or _NUM_COMMA.match(c) for c in cells0):  # no header row
        delim, decimal = _detect([first] + sample[: _SAMPLE - 1], None, src, h + 1)
        width = len(_split_cells(first, delim))
        header = [str(i) for i in range(width)]
        prev = [ln for ln in lines[:h] if ln.startswith("#")]
        if prev:  # np.savetxt-style '# t,u,y' header (its own delimiter may differ from the data's)
            line = prev[-1].lstrip("#").strip()
            for d in dict.fromkeys((delim, ",", ";", "\t", " ")):
                names = _split_cells(line, d)
                if len(names) == width and all(n and not _NUM.match(n) for n in names):
                    header = names
                    break
        return delim, decimal, False, header, h
    if not sample:
        raise DataError(f"{src}: file has a header but no data rows")
    delim, decimal = _detect(sample, first, src, content[1] + 1)
    return delim, decimal, True, _split_cells(first, delim), content[1]


def _fast_layout(
    raw: bytes, source, src: str, delim: str, decimal: str, has_header: bool, header: list[str], first_data: int
) -> CsvTable | None:
    """The common case without a full scan: no quotes, comments, blank or indented lines after the header.
    Every row has ``width`` cells when the first does, the delimiters total ``rows * (width - 1)`` and no
    row has more (pandas refuses that while parsing every column: :meth:`CsvTable.prefetch`). ``None`` when
    the file is not of this kind (the full check then runs)."""
    if delim == " ":
        return None
    width = len(header)
    start = 0
    for _ in range(first_data):  # byte offset of the first data line
        k = raw.find(b"\n", start)
        if k < 0:
            return None
        start = k + 1
    end = len(raw)
    while end > start and raw[end - 1] in b" \t\n":
        end -= 1
    if end <= start:
        return None
    if raw.find(b'"', start, end) >= 0:
        return None
    b = np.frombuffer(raw, dtype=np.uint8, count=end, offset=0)[start:]
    nl = np.flatnonzero(b == 10)
    after = b[nl + 1] if nl.size else nl  # first byte of every following line: no '#', blank or indent
    if np.isin(after, np.frombuffer(b"#\n \t", dtype=np.uint8)).any():
        return None
    first_end = raw.find(b"\n", start, end)
    first_line = raw[start : end if first_end < 0 else first_end].decode("utf-8")
    if first_line.startswith((" ", "\t", "#")) or len(_split_cells(first_line, delim)) != width:
        return None
    rows = nl.size + 1
    if int(np.count_nonzero(b == ord(delim))) != rows * (width - 1):
        return None
    line_no = np.arange(first_data + 1, first_data + 1 + rows)
    return CsvTable(src, header, source, line_no, delim, decimal, has_header, first_data, verify_width=True)


def parse_csv(p: Path, src: str, fast: bool = True) -> CsvTable:
    """Read and check the structure of a CSV file (see the module doc); numbers are parsed on demand."""
    try:
        return _parse_csv(p, src, fast)
    except csv.Error as exc:  # e.g. a quoted field beyond the csv module's field-size limit
        raise DataError(f"{src}: cannot split a line into cells ({exc})") from None
    except UnicodeDecodeError as exc:
        raise DataError(f"{src}: not a UTF-8 text CSV file ({exc.reason} at byte {exc.start} of a line)") from None


def _parse_csv(p: Path, src: str, fast: bool = True) -> CsvTable:
    """Read and check the structure of a CSV file (see the module doc); numbers are parsed on demand.

    One vectorised pass finds the newlines and delimiters; a well-formed data block is then checked by the
    order of its separators alone (``width - 1`` delimiters before every newline)."""
    raw, source = _load(p, src)
    delim, decimal, has_header, header, first_data = _head_layout(raw, src)
    width = len(header)
    if fast:
        table = _fast_layout(raw, source, src, delim, decimal, has_header, header, first_data)
        if table is not None:
            return table
    b = np.frombuffer(raw, dtype=np.uint8)
    dbyte = ord(delim) if delim != " " else 10
    sep = np.flatnonzero((b == 10) | (b == dbyte))
    kinds = b[sep]
    is_nl = kinds == 10
    nl = sep[is_nl]
    starts = np.concatenate(([0], nl + 1))
    ends = np.concatenate((nl, [b.size]))
    if starts[-1] >= b.size:  # the file ends with a newline: no final empty line
        starts, ends = starts[:-1], ends[:-1]
    first_char = np.where(starts < ends, b[np.minimum(starts, b.size - 1)], 0)
    blank = ends == starts
    lead = np.flatnonzero(~blank & ((first_char == 32) | (first_char == 9)))  # lines starting with blanks
    for i in lead:  # rare outside space-delimited files; those are small in practice
        stripped = raw[starts[i] : ends[i]].strip()
        blank[i] = not stripped
        first_char[i] = stripped[0] if stripped else 0
    comment = (first_char == ord("#")) & ~blank
    content = np.flatnonzero(~blank & ~comment)
    data_idx = content[1:] if has_header else content
    if data_idx.size == 0:
        raise DataError(f"{src}: file has a header but no data rows")
    last = int(data_idx[-1])
    h = int(content[0])
    inner_blank = np.flatnonzero(blank[h:last]) + h  # blank lines between data rows are refused
    if inner_blank.size:
        ln = int(inner_blank[0]) + 1
        raise DataError(
            f"{src}: line {ln} is blank between data rows; remove it (or start it with #) so no row is dropped silently"
        )
    body_start = int(starts[data_idx[0]])
    contiguous = not comment[data_idx[0] : last].any()
    if raw.find(b'"', body_start) >= 0 or delim == " ":  # quotes or runs of spaces: line by line
        counts = np.array([len(_split_cells(raw[starts[i] : ends[i]].decode("utf-8"), delim)) for i in data_idx])
    elif contiguous:  # delimiters between consecutive newlines of the data block
        lo, hi = np.searchsorted(sep, [body_start, int(ends[last])])
        block_nl = np.flatnonzero(is_nl[lo : hi + 1][: hi - lo + 1])
        if block_nl.size < data_idx.size:  # the last line has no newline
            block_nl = np.append(block_nl, hi - lo)
        counts = np.diff(np.concatenate(([-1], block_nl[: data_idx.size]))) - 1 + 1
    else:
        pos = sep[~is_nl]
        counts = np.searchsorted(pos, ends[data_idx]) - np.searchsorted(pos, starts[data_idx]) + 1
    bad = np.flatnonzero(counts != width)
    if bad.size:
        k = int(bad[0])
        ln = int(data_idx[k]) + 1
        what = "more" if counts[k] > width else "fewer"
        hint = " (a decimal comma under a ',' delimiter?)" if counts[k] > width and delim == "," else ""
        raise DataError(
            f"{src}: line {ln} (row {k + 1 + has_header}) has {int(counts[k])} cells, {what} than the "
            f"{width} of the {'header' if has_header else 'first row'}{hint}"
        )
    skip = 0
    if not contiguous:  # comment lines among the data: keep only the data lines
        body = b"\n".join(raw[starts[i] : ends[i]] for i in data_idx) + b"\n"
    else:  # the data lines are contiguous: parse them in place (no copy of the buffer)
        body, skip = source, int(data_idx[0])
    table = CsvTable(src, header, body, data_idx + 1, delim, decimal, has_header, skip)
    if contiguous and comment[last:].any():
        table.nrows = int(data_idx.size)
    return table
