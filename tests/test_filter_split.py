"""The MEKF and USQUE, each its book's page (issue 31): their classes stay
small, the hard-iron states' bookkeeping and USQUE's IMU updates live beside
them, and every name the project imports from their modules is still there."""
import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Lines a class and a function of these modules may span.
CLASS_LINES, FUNCTION_LINES = 200, 60
MODULES = ("mekf", "usque", "magnetometer_bias")


def names_imported_from(module: str):
    for folder in ("dynamics", "sensors", "estimators", "benchmarks", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if isinstance(node, ast.ImportFrom) and node.module == module:
                    yield from (alias.name for alias in node.names)


@pytest.mark.parametrize("module", MODULES)
def test_each_class_and_function_stays_small(module):
    text = (ROOT / "estimators" / f"{module}.py").read_text()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ClassDef):
            assert node.end_lineno - node.lineno + 1 <= CLASS_LINES, node.name
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            assert node.end_lineno - node.lineno + 1 <= FUNCTION_LINES, node.name


@pytest.mark.parametrize("module", ["estimators.mekf", "estimators.usque"])
def test_every_name_the_project_imports_from_the_filters_is_there(module):
    imported = set(names_imported_from(module))
    assert imported
    assert not imported - set(dir(importlib.import_module(module)))


def test_the_filters_keep_their_mixins_methods():
    from estimators import USQUE, MultiplicativeEKF
    for name in ("settings_from_scenario", "_configure_magnetometer_bias", "_reads_hard_iron"):
        assert hasattr(MultiplicativeEKF, name), name
    for name in ("estimate", "_gravity_update", "_rest_update", "_heading_update"):
        assert hasattr(USQUE, name), name
