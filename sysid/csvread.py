"""Strict, vectorised CSV reading for :func:`sysid.io.read_record` (issues 18 item 5 and 19 item 2).

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
read stays within about 1.5x of ``pandas.read_csv`` alone (``benchmarks/perf/test_csv_read.py``).
"""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path

import numpy as np

from sysid.errors import DataError

__all__ = ["CsvTable", "parse_csv", "TIME_COLUMNS"]

#: time-column names (lower case) and the factor to seconds
TIME_COLUMNS = {"t": 1.0, "time": 1.0, "t_s": 1.0, "time_s": 1.0, "t_ms": 1e-3, "time_ms": 1e-3,
                "t_us": 1e-6, "time_us": 1e-6}
NA_VALUES = ["", "nan", "NaN", "NAN", "NA", "null", "NULL"]
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf|infinity)$", re.IGNORECASE)
_NUM_COMMA = re.compile(r"^[+-]?(\d+,?\d*|,\d+)([eE][+-]?\d+)?$")
_SAMPLE = 200  # lines used to detect the delimiter and decimal mark


class CsvTable:
    """Header and column access of a parsed CSV file; columns are parsed on demand."""

    def __init__(self, src: str, header: list[str], body: bytes, line_no: np.ndarray, delimiter: str,
                 decimal: str, has_header: bool):
        self.src, self.header, self.body, self.line_no = src, header, body, line_no
        self.delimiter, self.decimal, self.has_header = delimiter, decimal, has_header
        self.index = {name: i for i, name in enumerate(header) if name != ""}
        self._cache: dict[int, np.ndarray] = {}

    def __len__(self) -> int:
        return int(self.line_no.size)

    def columns(self, names: list[str]) -> list[np.ndarray]:
        """Parse the named columns (one pandas pass for all of them) as float64 arrays."""
        for n in names:
            if self.header.count(n) > 1:
                raise DataError(f"{self.src}: column {n!r} appears {self.header.count(n)} times in the header; "
                                "rename the copies")
        idx = [self.index[n] for n in names]
        todo = sorted({i for i in idx if i not in self._cache})
        if todo:
            self._parse(todo)
        return [self._cache[i] for i in idx]

    def _parse(self, cols: list[int]) -> None:
        import pandas as pd

        sep = r"\s+" if self.delimiter == " " else self.delimiter
        try:
            df = pd.read_csv(io.BytesIO(self.body), sep=sep, decimal=self.decimal, header=None, usecols=cols,
                             na_values=NA_VALUES, keep_default_na=False,
                             skip_blank_lines=False, engine="c", quotechar='"', low_memory=False)
        except Exception as exc:  # structural problems were found before; this is a last guard
            raise DataError(f"{self.src}: cannot parse the data rows ({type(exc).__name__}: "
                            f"{str(exc).splitlines()[-1] if str(exc) else ''})") from None
        if len(df) != len(self):
            raise DataError(f"{self.src}: {len(df)} data rows parsed, {len(self)} expected; check quotes in the file")
        for c in cols:
            s = df[c]
            if s.dtype.kind not in "fiu":
                num = pd.to_numeric(s, errors="coerce")
                bad = np.flatnonzero(num.isna().to_numpy() & s.notna().to_numpy())
                if bad.size:
                    k = int(bad[0])
                    name = self.header[c]
                    raise DataError(f"{self.src}: column {name!r} row {k + 1 + self.has_header} is not a number: "
                                    f"{s.iloc[k]!r} (line {int(self.line_no[k])}, column {c + 1})"
                                    + ("; decimal commas need ';', tab or space as delimiter"
                                       if self.decimal == "." and re.match(r"^-?\d+,\d+$", str(s.iloc[k])) else ""))
                s = num
            self._cache[c] = s.to_numpy(dtype=np.float64, na_value=np.nan)


def _decode(raw: bytes, src: str) -> bytes:
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in raw[:65536]:
        raise DataError(f"{src}: not a UTF-8 text CSV file (UTF-16 or binary); save it as UTF-8")
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DataError(f"{src}: not a UTF-8 text CSV file (byte {exc.start} does not decode)") from None
    if b"\r" in raw:
        raw = raw.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return raw


def _split_cells(line: str, delim: str) -> list[str]:
    if delim == " ":
        return [c.strip('"') for c in line.split()]
    return [c.strip() for c in next(csv.reader([line], delimiter=delim, quotechar='"'))]


def _detect(lines: list[str], header_line: str | None, src: str, first_line: int) -> tuple[str, str]:
    """Delimiter and decimal mark from sample data lines (and the header)."""
    for d in ("\t", ";", ","):
        counts = {ln.count(d) for ln in lines}
        if len(counts) == 1 and counts.pop() >= 1:
            delim = d
            break
    else:
        widths = {len(ln.split()) for ln in lines}
        if len(widths) == 1 and widths.pop() >= 2:
            delim = " "
        elif all(ln.count(",") == 0 and ln.count(";") == 0 and ln.count("\t") == 0 and len(ln.split()) == 1
                 for ln in lines):
            delim = ","  # one column
        else:
            raise DataError(f"{src}: cannot tell the delimiter: lines {first_line}.. split into different numbers "
                            "of cells by ',', ';', tab and spaces alike; see docs/data-files.md")
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


def parse_csv(p: Path, src: str) -> CsvTable:
    """Read and check the structure of a CSV file (see the module doc); numbers are parsed on demand."""
    raw = _decode(p.read_bytes(), src)
    b = np.frombuffer(raw, dtype=np.uint8)
    nl = np.flatnonzero(b == 10)
    starts = np.concatenate(([0], nl + 1))
    ends = np.concatenate((nl, [b.size]))
    if starts[-1] >= b.size:  # the file ends with a newline: no final empty line
        starts, ends = starts[:-1], ends[:-1]
    if starts.size == 0:
        raise DataError(f"{src}: file has no rows")
    space = (b == 32) | (b == 9)
    nonspace_cum = np.concatenate(([0], np.cumsum(~space)))
    blank = (nonspace_cum[ends] - nonspace_cum[starts]) == 0
    first_char = np.where(starts < ends, b[np.minimum(starts, b.size - 1)], 0)
    comment = (first_char == ord("#")) & ~blank
    content = np.flatnonzero(~blank & ~comment)
    if content.size == 0:
        raise DataError(f"{src}: file has no rows (only blank or # comment lines)")

    def text(i: int) -> str:
        return raw[starts[i]:ends[i]].decode("utf-8")

    h = int(content[0])
    sample = [text(int(i)) for i in content[1:_SAMPLE + 1]]
    first = text(h)
    # header or not: a first content line with any non-numeric, non-empty cell is the header
    probe_delim, _ = _detect([first] + sample[:1] if sample else [first], None, src, h + 1) if sample else (",", ".")
    cells0 = _split_cells(first, probe_delim)
    numeric_first = all(c == "" or _NUM.match(c) or _NUM_COMMA.match(c) for c in cells0)
    if numeric_first:
        data_idx = content
        delim, decimal = _detect([first] + sample[:_SAMPLE - 1], None, src, h + 1)
        width = len(_split_cells(first, delim))
        header = [str(i) for i in range(width)]
        has_header = False
        prev = [i for i in range(h) if comment[i]]
        if prev:  # np.savetxt-style '# t,u,y' header
            names = _split_cells(text(prev[-1]).lstrip("#").strip(), delim)
            if len(names) == width and all(n and not _NUM.match(n) for n in names):
                header = names
    else:
        data_idx = content[1:]
        if data_idx.size == 0:
            raise DataError(f"{src}: file has a header but no data rows")
        delim, decimal = _detect(sample, first, src, int(data_idx[0]) + 1)
        header = _split_cells(first, delim)
        has_header = True
        width = len(header)
    # blank lines between data rows are refused (trailing blank lines are fine)
    last = int(data_idx[-1])
    inner_blank = np.flatnonzero(blank[h:last]) + h
    if inner_blank.size:
        ln = int(inner_blank[0]) + 1
        raise DataError(f"{src}: line {ln} is blank between data rows; remove it (or start it with #) so no row "
                        "is dropped silently")
    # cells per data line (vectorised; a file with quotes in its data rows is checked line by line)
    body_start = int(starts[data_idx[0]])
    body = raw[body_start:int(ends[last])] + b"\n"
    if b'"' in body:
        counts = np.array([len(_split_cells(text(int(i)), delim)) for i in data_idx])
    elif delim == " ":
        field_start = ~space & (b != 10) & np.concatenate(([True], space[:-1] | (b[:-1] == 10)))
        fs_cum = np.concatenate(([0], np.cumsum(field_start)))
        counts = fs_cum[ends[data_idx]] - fs_cum[starts[data_idx]]
    else:
        d_cum = np.concatenate(([0], np.cumsum(b == ord(delim))))
        counts = d_cum[ends[data_idx]] - d_cum[starts[data_idx]] + 1
    bad = np.flatnonzero(counts != width)
    if bad.size:
        k = int(bad[0])
        ln = int(data_idx[k]) + 1
        what = "more" if counts[k] > width else "fewer"
        hint = " (a decimal comma under a ',' delimiter?)" if counts[k] > width and delim == "," else ""
        raise DataError(f"{src}: line {ln} (row {k + 1 + has_header}) has {int(counts[k])} cells, {what} than the "
                        f"{width} of the {'header' if has_header else 'first row'}{hint}")
    if comment[data_idx[0]:].any():  # comment lines among the data: keep only the data lines
        body = b"\n".join(raw[starts[i]:ends[i]] for i in data_idx) + b"\n"
    return CsvTable(src, header, body, data_idx + 1, delim, decimal, has_header)
