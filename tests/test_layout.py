"""The folders tell the story: imports point one way between the packages."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dynamics", "sensors", "estimators", "benchmarks")
#: package → the project packages it may import.
ALLOWED = {
    "dynamics": set(),
    "sensors": {"dynamics"},
    "estimators": {"dynamics"},
    "benchmarks": {"dynamics", "sensors", "estimators"},
}


def project_imports(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        for name in names:
            top = name.split(".")[0]
            if top in PACKAGES:
                yield top


@pytest.mark.parametrize("package", PACKAGES)
def test_imports_point_one_way(package):
    for path in (ROOT / package).rglob("*.py"):
        for imported in project_imports(path):
            assert imported == package or imported in ALLOWED[package], \
                f"{path.relative_to(ROOT)} imports {imported}"
