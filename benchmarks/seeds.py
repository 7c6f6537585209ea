"""Seed lists as users type them: ``0``, ``0-19``, ``1,5,9`` or a mix (``0-4,9``)."""
from __future__ import annotations

import re

from dynamics.validation import MAX_SEED, InvalidParameterError

_RULE = "must be N, N-M or N,M,... of whole numbers >= 0 (e.g. 0, 0-19, 1,5,9)"
_PART = re.compile(r"^(\d+)(?:-(\d+))?$")
#: A guard against typing 0-1000000000 by mistake.
MAX_SEEDS = 1_000_000


def parse_seeds(text: str, name: str = "seeds") -> tuple[int, ...]:
    """The seeds of ``text``, in the order given, without repeats.

    >>> parse_seeds("0-3,7")
    (0, 1, 2, 3, 7)
    """
    seeds: dict[int, None] = {}
    parts = str(text).replace(" ", "").split(",")
    for part in parts:
        match = _PART.match(part)
        if not match:
            raise InvalidParameterError(name, text, _RULE)
        first = int(match.group(1))
        last = int(match.group(2)) if match.group(2) is not None else first
        if last > MAX_SEED:
            raise InvalidParameterError(name, text, f"seeds must be at most 2^63 - 1 = {MAX_SEED}")
        if last < first:
            raise InvalidParameterError(name, text, f"range {part} runs backwards; {_RULE}")
        if len(seeds) + last - first + 1 > MAX_SEEDS:
            raise InvalidParameterError(name, text, f"must name at most {MAX_SEEDS} seeds")
        seeds.update(dict.fromkeys(range(first, last + 1)))
    return tuple(seeds)


def format_seeds(seeds) -> str:
    """The shortest ``parse_seeds`` text for ``seeds``.

    >>> format_seeds([0, 1, 2, 3, 7])
    '0-3,7'
    """
    seeds = list(seeds)
    parts, start = [], 0
    for i in range(1, len(seeds) + 1):
        if i == len(seeds) or seeds[i] != seeds[i - 1] + 1:
            first, last = seeds[start], seeds[i - 1]
            parts.append(str(first) if first == last else f"{first}-{last}")
            start = i
    return ",".join(parts)


#: The training seeds of ``--tuned``, unless given: away from the seeds a
#: user runs (0, 1, …).
DEFAULT_TRAINING_SEEDS = tuple(range(100, 105))
