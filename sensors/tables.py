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
    for name in frame.columns:            # ISO 8601 times: integer nanoseconds (UTC)
        if frame[name].dtype.kind not in "iufb" and _ISO_TIME.match(str(frame[name].dropna().iloc[0])
                                                           if frame[name].notna().any() else ""):
            frame[name] = pd.to_datetime(frame[name], format="ISO8601", utc=True
                                         ).dt.as_unit("ns").astype("int64")
    if not header:            # a trailing separator leaves an empty last column: none
        if frame.shape[1] > 1 and frame.iloc[:, -1].isna().all():
            frame = frame.iloc[:, :-1]
        frame.columns = [str(number) for number in range(1, frame.shape[1] + 1)]
    return frame


def csv_layout(data: Path) -> tuple:
    """``(lines skipped, separator, decimal mark, whether it has a header)``
    of a CSV, read from its first lines: the preamble's count, or with a
    row of units under the header (every cell text), the list of both."""
    import gzip
    opened = gzip.open if data.suffix.lower() == ".gz" else open
    with opened(data, "rt", encoding="utf-8", errors="replace") as lines:
        opening = [line.rstrip("\r\n") for _, line in zip(range(1000), lines)]
    skip = next((index for index, line in enumerate(opening)
                 if not line.lstrip().startswith(COMMENT_PREFIXES)), len(opening))
    first = [line for line in opening[skip:skip + LAYOUT_LINES + 1] if line.strip()]
    if not first:
        return skip, ",", ".", True
    separator = _separator(first)
    cells = _cells(first[-1] if len(first) > 1 else first[0], separator)
    decimal = "," if separator != "," and any(re.fullmatch(r"[+-]?\d*,\d+([eE][+-]?\d+)?", cell)
                                              for cell in cells) else "."
    header = not all(_NUMBER.match(cell) for cell in _cells(first[0], separator) if cell)
    if header:                # a row of units under the names (s, rad/s, …): skipped
        at = opening.index(first[0], skip) + 1
        units = [index for index in range(at, len(opening)) if opening[index].strip()][:1]
        if units and not any(_NUMBER.match(cell) for cell in _cells(opening[units[0]],
                                                                     separator)):
            skip = [*range(skip), units[0]]
    return skip, separator, decimal, header


def _separator(lines: list) -> str:
    """The first of :data:`SEPARATORS` every line holds as often as the
    first (one more allowed: a trailing one), quoted text aside, and that
    leaves the last line's cells numbers (``1,25;-0,5``: the semicolon, not
    the decimal comma); else runs of spaces."""
    consistent = []
    for separator in SEPARATORS:
        counts = [re.sub(r'"[^"]*"', "", line).count(separator) for line in lines]
        if counts[0] > 0 and all(count - counts[0] in (0, 1) for count in counts):
            consistent.append(separator)
    if len({len(line.split()) for line in lines}) == 1:
        consistent.append(SPACES)
    numbers = [separator for separator in consistent
               if all(_NUMBER.match(cell) for cell in _cells(lines[-1], separator) if cell)]
    return (numbers or consistent or [SPACES])[0]


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
