"""A logger's file read into its columns, whatever its format: CSV or
Parquet (pandas), ``.npz`` (numpy), ``.mat`` (scipy), HDF5 (h5py, an
optional extra). What :mod:`sensors.declared` reads a declaration's
columns from; a file that cannot be read is one line naming it."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dynamics.validation import InvalidParameterError


def read_table(data: Path) -> dict:
    """The file's columns, name → array (a CSV's or Parquet's columns, an
    archive's arrays, a MATLAB file's variables, an HDF5 file's datasets)."""
    suffix = data.suffix.lower()
    try:
        if suffix in (".csv", ".txt", ".parquet"):
            import pandas as pd
            frame = pd.read_parquet(data) if suffix == ".parquet" else \
                pd.read_csv(data, skiprows=_comment_lines(data))
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
    raise InvalidParameterError("recording.file", str(data), "must be .csv, .parquet, .npz, "
                                ".mat, .h5 or .hdf5")


def _comment_lines(data: Path) -> int:
    """How many lines a CSV opens with that begin with ``#`` (a logger's
    preamble: its device, its settings), skipped before the header."""
    count = 0
    with open(data, encoding="utf-8", errors="replace") as lines:
        for line in lines:
            if not line.startswith("#"):
                break
            count += 1
    return count


def _read_hdf5(data: Path) -> dict:
    import h5py
    found = {}
    with h5py.File(data, "r") as handle:
        handle.visititems(lambda name, item: found.__setitem__(name, item[()])
                          if isinstance(item, h5py.Dataset) else None)
    return found
