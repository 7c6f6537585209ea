"""Files the project ships beside its code — the flight scenario, the recorded
datasets — found in the source tree (a clone, an editable install) or where
``pip install .`` put them (``share/attitude-bench`` under the environment's
prefix; see ``[options.data_files]`` in ``setup.cfg``).
"""
from __future__ import annotations

import sys
import sysconfig
from pathlib import Path

#: The project's root in a source tree: the folder holding ``benchmarks/``.
SOURCE_ROOT = Path(__file__).resolve().parents[1]
INSTALLED_FOLDER = Path("share") / "attitude-bench"
FLIGHT_SCENARIO = "scenarios/flight.toml"


def shipped_file(relative: str) -> Path:
    """The shipped file ``relative`` (e.g. ``"scenarios/flight.toml"``).

    Raises ``FileNotFoundError`` naming every place looked in.
    """
    places = [SOURCE_ROOT / relative]
    for prefix in dict.fromkeys((sysconfig.get_path("data"), sys.prefix)):
        places.append(Path(prefix) / INSTALLED_FOLDER / relative)
    for place in places:
        if place.is_file():
            return place
    raise FileNotFoundError(f"{relative} is not in the source tree or the installation "
                            f"(looked in {', '.join(str(p.parent) for p in places)})")
