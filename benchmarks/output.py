"""Writing results: every file appears whole or not at all; progress on the terminal.

Each writer renders to a temporary file in the destination folder and
renames it into place (``os.replace`` is atomic on one file system), so an
interrupted run never leaves a half-written CSV or PNG behind.
"""
from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _atomic_write_bytes(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
        # mkstemp makes owner-only files; results should be as readable as any file.
        os.chmod(temporary, 0o666 & ~_umask())
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise


def check_output_folder(out, files=()) -> Path:
    """Refuse, before any work, an output folder that cannot take the results.

    ``out`` must be a folder or creatable as one (its nearest existing
    ancestor a writable folder), and writable; none of ``files`` (names in
    it) may be a folder. Raises ``ValueError`` with one line naming ``out``.
    """
    from dynamics.validation import InvalidParameterError
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InvalidParameterError("out", str(out), "is a file, not a folder; choose a folder")
    existing = out
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if not existing.is_dir():
        raise InvalidParameterError("out", str(out), f"cannot be created: {existing} is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InvalidParameterError("out", str(out), f"cannot be written: {existing} is not "
                                    "writable")
    for name in files:
        if (out / name).is_dir():
            raise InvalidParameterError("out", str(out), f"holds a folder named {name} where "
                                        "the results file goes; move it or choose another folder")
    return out


def write_text(path, text: str) -> None:
    _atomic_write_bytes(Path(path), text.encode("utf-8"))


def write_bytes(path, data: bytes) -> None:
    _atomic_write_bytes(Path(path), data)


def write_csv(path, header, rows, digits: int = 12) -> None:
    """A CSV with ``header`` and ``rows``; floats keep ``digits`` significant
    digits (17 round-trips a double exactly)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        writer.writerow([f"{value:.{digits}g}" if isinstance(value, float) else value
                         for value in row])
    write_text(path, buffer.getvalue())


def write_figure(path, figure, dpi: int = 120) -> None:
    """Save a matplotlib figure (format from the suffix)."""
    _atomic_write_bytes(Path(path), figure_bytes(path, figure, dpi))


def figure_bytes(path, figure, dpi: int = 120) -> bytes:
    """A matplotlib figure rendered as ``path``'s format would hold it: render
    first, write after, so that a figure that cannot be drawn leaves no
    other file of its command half-written."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format=Path(path).suffix.lstrip(".") or "png", dpi=dpi)
    return buffer.getvalue()


@contextlib.contextmanager
def atomic_path(path):
    """A temporary path beside ``path`` for writers that insist on a file name
    (e.g. matplotlib's animation writers); renamed into place on success,
    removed on failure."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.",
                                         suffix=path.suffix)
    os.close(handle)
    try:
        yield temporary
        os.chmod(temporary, 0o666 & ~_umask())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise


def progress(iterable=None, *, total=None, desc: str = "", quiet: bool = False, unit="it"):
    """``iterable`` wrapped in a progress bar (or a bar to ``update`` by hand).

    tqdm's ``disable=None`` already hides the bar when stderr is not a terminal;
    ``quiet`` hides it everywhere.
    """
    from tqdm import tqdm      # here: the command line starts without it
    return tqdm(iterable, total=total, desc=desc, unit=unit, leave=False,
                disable=True if quiet else None, dynamic_ncols=True)


def write_json(path: Path, data: dict) -> None:
    """``data`` as JSON, a NaN or an infinity written as null (JSON has neither)."""
    write_text(path, json.dumps(_json_safe(data), indent=2, allow_nan=False) + "\n")


def _json_safe(value):
    if isinstance(value, dict):
        return {key: _json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return _json_safe(value.item())
    if isinstance(value, np.ndarray):
        return _json_safe(value.tolist())
    return value
