"""A logger's file read into its columns, whatever its format: CSV or
Parquet (pandas), ``.npz`` (numpy), ``.mat`` (scipy), HDF5 (h5py, an
optional extra). What :mod:`sensors.declared` reads a declaration's
columns from; a file that cannot be read is one line naming it.

A CSV (or ``.txt``) is read as its logger wrote it (:func:`csv_layout`):
a preamble of ``#`` or ``//`` lines (Xsens MT Manager's) skipped; the
separator found in its lines (comma, semicolon, tab, bar, or spaces);
decimal commas where the separator is not a comma (a European locale's
``2,5E-03;1,1E-02``, phyphox's); a row of units under the header
(``s, rad/s, …``) skipped; a trailing separator on each line (Arduino
sketches') no column; and a file without a header (every cell of
its first line a number) with its columns named ``"1"``, ``"2"``, … in
their order.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from dynamics.validation import InvalidParameterError


def read_table(data: Path) -> dict:
    """The file's columns, name → array (a CSV's or Parquet's columns, an
    archive's arrays, a MATLAB file's variables, an HDF5 file's datasets)."""
    suffix = data.suffix.lower()
    if suffix == ".gz" and data.with_suffix("").suffix.lower() in (".csv", ".txt"):
        suffix = ".csv"               # compressed: pandas and gzip read it as it is
    try:
        if suffix in (".csv", ".txt", ".parquet"):
            import pandas as pd
            frame = pd.read_parquet(data) if suffix == ".parquet" else _read_csv(data)
            return {str(name): frame[name].to_numpy() for name in frame.columns}
        if suffix == ".npz":
            with np.load(data, allow_pickle=False) as archive:
                return {key: archive[key] for key in archive.files}
        if suffix == ".mat":
            from scipy.io import loadmat
            # MATLAB keeps a vector as a (1, N) row or an (N, 1) column: one column
            return {key: value.reshape(-1) if value.ndim == 2 and 1 in value.shape else value
                    for key, value in loadmat(data).items() if not key.startswith("__")}
        if suffix in (".h5", ".hdf5"):
            return _read_hdf5(data)
    except ImportError as err:   # pandas names no module where Parquet has no engine
        needed = err.name or ("pyarrow" if suffix == ".parquet" else str(err))
        raise InvalidParameterError("recording.file", str(data), f"needs {needed}, which is "
                                    "not installed (pip install it)") from None
    except Exception as err:     # a corrupt or foreign file: one line, whatever the reader
        raise InvalidParameterError("recording.file", str(data), f"cannot be read "
                                    f"({type(err).__name__}: {err})") from None
    spreadsheet = " (save a spreadsheet as CSV)" if suffix in (".xlsx", ".xls", ".ods") else ""
    raise InvalidParameterError("recording.file", str(data), "must be .csv (or .csv.gz), "
                                f".parquet, .npz, .mat, .h5 or .hdf5{spreadsheet}")


#: What a CSV's preamble lines begin with (a logger's device and settings).
COMMENT_PREFIXES = ("#", "//")
#: The separators a CSV's lines are tried for, in this order; spaces last.
SEPARATORS = (",", ";", "\t", "|")
#: Runs of spaces (or tabs) as one separator, pandas' way.
SPACES = r"\s+"
#: The encodings a CSV is read in, in turn: UTF-8 (its byte-order mark
#: too), then Windows' Western one (Excel's "CSV" on Windows: µ as 0xB5).
ENCODINGS = ("utf-8-sig", "cp1252")
#: A separator is the file's where its count is the same on this share of
#: the data lines (a row cut short, a trailing one on some, aside).
STEADY_SHARE = 0.8
#: How many of the first data lines the layout is read from.
LAYOUT_LINES = 20
#: A cell holding an ISO 8601 date and time (``2024-05-01T12:00:00.005Z``),
#: read as integer nanoseconds since 1970 (UTC): ``time_unit = "ns"``.
_ISO_TIME = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}")
_NUMBER = re.compile(r"^[+-]?(\d+([.,]\d*)?|[.,]\d+)([eE][+-]?\d+)?$")


def _read_csv(data: Path):
    import pandas as pd
    skip, separator, decimal, header = csv_layout(data)
    for encoding in ENCODINGS:
        try:
            frame = pd.read_csv(data, skiprows=skip, sep=separator, decimal=decimal,
                                index_col=False, header=0 if header else None,
                                skipinitialspace=True, encoding=encoding)
            break
        except UnicodeDecodeError:
            if encoding == ENCODINGS[-1]:
                raise
    for name in frame.columns:
        if frame[name].dtype.kind not in "iufb":
            frame[name] = _text_column(frame[name])
    if not header:            # a trailing separator leaves an empty last column: none
        if frame.shape[1] > 1 and frame.iloc[:, -1].isna().all():
            frame = frame.iloc[:, :-1]
        frame.columns = [str(number) for number in range(1, frame.shape[1] + 1)]
    return frame


def _text_column(column):
    """A column pandas read as text: ISO 8601 times as integer nanoseconds
    (UTC; floats with NaN where a cell is empty), numbers whose last cell
    alone is not one (a line cut short mid-number: ``-``, ``1.2e``) with
    that cell empty; else as it is."""
    import pandas as pd
    present = column.dropna()
    if len(present) and _ISO_TIME.match(str(present.iloc[0])):
        times = pd.to_datetime(column, format="ISO8601", utc=True).dt.as_unit("ns")
        return times.astype("int64") if times.notna().all() else \
            times.astype("int64").where(times.notna()).astype(float)
    numbers = pd.to_numeric(column, errors="coerce")
    failed = numbers.isna() & column.notna()
    if len(column) > 1 and failed.any() and list(failed[failed].index) == [column.index[-1]]:
        return numbers
    return column


def csv_layout(data: Path) -> tuple:
    """``(lines skipped, separator, decimal mark, whether it has a header)``
    of a CSV, read from its first lines: the preamble's count, or with a
    row of units under the header (every cell text), the list of both."""
    import gzip
    opened = gzip.open if data.suffix.lower() == ".gz" else open
    with opened(data, "rt", encoding="utf-8-sig", errors="replace") as lines:
        opening = [line.rstrip("\r\n") for _, line in zip(range(1000), lines)]
    skip = next((index for index, line in enumerate(opening)
                 if not line.lstrip().startswith(COMMENT_PREFIXES)), len(opening))
    first = [line for line in opening[skip:skip + LAYOUT_LINES + 1] if line.strip()]
    if not first:
        return skip, ",", ".", True
    separator = _separator(first)
    data_cells = [cell for line in first[1:] or first for cell in _cells(line, separator)]
    decimal = "," if separator != "," and any(re.fullmatch(r"[+-]?\d*,\d+([eE][+-]?\d+)?", cell)
                                              for cell in data_cells) else "."
    names = [cell for cell in _cells(first[0], separator) if cell]
    header = not all(_NUMBER.match(cell) for cell in names) or _index_like(names)
    if header:                # a row of units under the names (s, rad/s, …): skipped
        at = opening.index(first[0], skip) + 1
        units = [index for index in range(at, len(opening)) if opening[index].strip()][:1]
        cells = _cells(opening[units[0]], separator) if units else []
        if cells and all(re.search(r"[A-Za-z°µ%/]", cell) and not _NUMBER.match(cell)
                         and cell.lower() != "nan" for cell in cells if cell) and any(cells):
            skip = [*range(skip), units[0]]
    return skip, separator, decimal, header


def _index_like(cells: list) -> bool:
    """Whether a first line of whole numbers counts its columns (0, 1, 2 …
    or 1, 2, 3 …: pandas' ``to_csv`` of an unnamed frame): a header."""
    try:
        numbers = [float(cell) for cell in cells]
    except ValueError:
        return False
    return numbers in (list(range(len(cells))), list(range(1, len(cells) + 1))) and \
        len(cells) > 1


def _separator(lines: list) -> str:
    """The first of :data:`SEPARATORS` that the data lines (the header
    aside) hold at a steady count in most of them (quoted text aside), and
    that leaves the last line's cells numbers (``1,25;-0,5``: the
    semicolon, not the decimal comma), runs of spaces counting too where
    every line splits at them alike into more than one cell; else a comma
    (one column)."""
    body = lines[1:] or lines
    steady = []
    for separator in SEPARATORS:
        counts = [re.sub(r'"[^"]*"', "", line).count(separator) for line in body]
        common = max(set(counts), key=counts.count)
        if common > 0 and counts.count(common) >= STEADY_SHARE * len(counts):
            steady.append(separator)
    widths = {len(line.split()) for line in lines}
    if len(widths) == 1 and widths.pop() > 1:
        steady.append(SPACES)
    numbers = [separator for separator in steady
               if all(_NUMBER.match(cell) for cell in _cells(body[-1], separator) if cell)]
    return (numbers or steady or [","])[0]


def _cells(line: str, separator: str) -> list:
    parts = re.split(separator, line.strip()) if separator == SPACES else line.split(separator)
    return [part.strip().strip('"') for part in parts]


def _read_hdf5(data: Path) -> dict:
    import h5py
    found = {}
    with h5py.File(data, "r") as handle:
        handle.visititems(lambda name, item: found.__setitem__(name, item[()])
                          if isinstance(item, h5py.Dataset) else None)
    return found
