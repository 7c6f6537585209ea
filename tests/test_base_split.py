"""The estimator base, split by concern (issue 31): every name the project
imports from ``estimators.base`` is still there, each module of the split
stays small, and a scenario's section still goes to the class it names."""
import ast
import importlib
from pathlib import Path
from types import SimpleNamespace

import pytest

from estimators import AttitudeEstimator, MultiplicativeEKF

ROOT = Path(__file__).resolve().parents[1]
#: The modules :class:`estimators.base.AttitudeEstimator` is put together from.
SPLIT = ("base", "settings", "readings", "stepping", "records", "gating")
#: Lines a module, a class and a function of the split may span.
MODULE_LINES, CLASS_LINES, FUNCTION_LINES = 500, 200, 60


def names_imported_from_the_base():
    for folder in ("dynamics", "sensors", "estimators", "benchmarks", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if isinstance(node, ast.ImportFrom) and node.module == "estimators.base":
                    yield from (alias.name for alias in node.names)


def test_every_name_the_project_imports_from_the_base_is_there():
    base = importlib.import_module("estimators.base")
    imported = set(names_imported_from_the_base())
    assert "AttitudeEstimator" in imported
    assert not imported - set(dir(base))
    assert all(hasattr(base, name) for name in base.__all__)


@pytest.mark.parametrize("module", SPLIT)
def test_each_module_of_the_split_stays_small(module):
    text = (ROOT / "estimators" / f"{module}.py").read_text()
    assert len(text.splitlines()) <= MODULE_LINES
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ClassDef):
            assert node.end_lineno - node.lineno + 1 <= CLASS_LINES, node.name
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            assert node.end_lineno - node.lineno + 1 <= FUNCTION_LINES, node.name


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
