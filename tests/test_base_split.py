"""The estimators split by concern (issue 31): every name the project
imports from ``estimators.base``, ``estimators.mekf`` and ``estimators.usque``
is still there, the filters keep their mixins' methods, and a scenario's
section still goes to the class it names. (The split's sizes are the house's
limits, checked for every module in ``tests/test_layout.py``.)"""
import ast
import importlib
from pathlib import Path
from types import SimpleNamespace

import pytest

from estimators import USQUE, AttitudeEstimator, MultiplicativeEKF
from tests.conftest import source_tree

ROOT = Path(__file__).resolve().parents[1]


def names_imported_from(module: str):
    for folder in ("dynamics", "sensors", "estimators", "benchmarks", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(source_tree(path)):
                if isinstance(node, ast.ImportFrom) and node.module == module:
                    yield from (alias.name for alias in node.names)


@pytest.mark.parametrize("module, surely", [("estimators.base", "AttitudeEstimator"),
                                            ("estimators.mekf", None),
                                            ("estimators.usque", None)])
def test_every_name_the_project_imports_from_a_split_module_is_there(module, surely):
    imported = set(names_imported_from(module))
    assert imported and (surely is None or surely in imported)
    found = importlib.import_module(module)
    assert not imported - set(dir(found))
    assert all(hasattr(found, name) for name in getattr(found, "__all__", ()))


def test_the_filters_keep_their_mixins_methods():
    for name in ("settings_from_scenario", "_configure_magnetometer_bias", "_reads_hard_iron"):
        assert hasattr(MultiplicativeEKF, name), name
    for name in ("estimate", "_gravity_update", "_rest_update", "_heading_update"):
        assert hasattr(USQUE, name), name


def test_a_section_goes_to_the_registry_class_it_names_and_to_no_namesake():
    options = SimpleNamespace(estimator_options={"mekf": {"output": "prior"},
                                                 "estimator": {"output": "prior"}})

    class Tuned(MultiplicativeEKF):          # a user's MEKF: still the MEKF's section
        pass

    class Namesake(AttitudeEstimator):       # a user's class that only shares the name
        name = "mekf"

    class Unnamed(AttitudeEstimator):        # the interface's placeholder name is none
        pass

    assert MultiplicativeEKF.scenario_section(options) == {"output": "prior"}
    assert Tuned.scenario_section(options) == {"output": "prior"}
    assert Namesake.scenario_section(options) == {}
    assert Unnamed.scenario_section(options) == {}
