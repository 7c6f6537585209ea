"""Progress bars: tqdm on a terminal, silent otherwise or when asked.

tqdm's ``disable=None`` already hides the bar when stderr is not a terminal;
``quiet`` hides it everywhere.
"""
from __future__ import annotations

from tqdm import tqdm


def progress(iterable=None, *, total=None, desc: str = "", quiet: bool = False, unit="it"):
    """``iterable`` wrapped in a progress bar (or a bar to ``update`` by hand)."""
    return tqdm(iterable, total=total, desc=desc, unit=unit, leave=False,
                disable=True if quiet else None, dynamic_ncols=True)
