"""The command line answers at once: its import, ``--help`` and a refused
argument load none of the heavy libraries (issue 32: < 0.5 s whole process,
measured by ``python -m benchmarks.perf``, never by a timed test)."""
import subprocess
import sys

import pytest

HEAVY = ("matplotlib", "numba", "pandas", "dask", "seaborn", "scipy", "filterpy")

PROBE = """
import sys
from benchmarks.cli import main
try:
    status = main({argv!r})
except SystemExit as exit:
    status = exit.code
print("STATUS", status)
print("LOADED", " ".join(sorted({{name.split('.')[0] for name in sys.modules}})))
"""


def _loaded(argv):
    done = subprocess.run([sys.executable, "-c", PROBE.format(argv=argv)], capture_output=True,
                          text=True, check=True)
    lines = dict(line.split(" ", 1) for line in done.stdout.splitlines()
                 if line.startswith(("STATUS", "LOADED")))
    return lines["STATUS"], set(lines["LOADED"].split())


@pytest.mark.parametrize("argv", [
    ["--help"], ["--version"], ["compare", "--help"], ["broad", "--help"],
    ["run", "--estimator", "nope"],                      # refused by the parser
    ["compare", "--tstop", "-1"],                        # refused by the scenario
    ["sweep", "--estimator", "ekf", "--param", "nope", "--values", "1"],
])
def test_help_and_refusals_import_nothing_heavy(argv):
    status, loaded = _loaded(argv)
    assert status in ("0", "2")
    assert not loaded & set(HEAVY), f"{argv} imported {sorted(loaded & set(HEAVY))}"


@pytest.mark.slow      # 4 s
def test_the_probe_sees_a_heavy_import_when_a_command_runs(tmp_path):
    """The check above can fail: a command that runs imports them."""
    status, loaded = _loaded(["run", "--estimator", "ekf", "--tstop", "0.05", "--out",
                              str(tmp_path), "--quiet"])
    assert status == "0" and {"matplotlib", "filterpy"} <= loaded


def test_every_catalogued_estimator_is_the_class_of_its_name():
    from estimators.registry import CATALOG, ESTIMATORS
    assert list(ESTIMATORS) == list(CATALOG)
    for name in CATALOG:
        assert ESTIMATORS[name].name == name


def test_a_class_registered_at_run_time_joins_the_registry_and_leaves_it():
    from estimators import DeadReckoning
    from estimators.registry import ESTIMATORS, check_estimator_name
    ESTIMATORS["mine"] = DeadReckoning
    try:
        assert list(ESTIMATORS)[-1] == "mine" and check_estimator_name("mine") == "mine"
    finally:
        del ESTIMATORS["mine"]
    assert "mine" not in ESTIMATORS
    with pytest.raises(KeyError):
        del ESTIMATORS["mekf"]                 # the catalogue's own stay
