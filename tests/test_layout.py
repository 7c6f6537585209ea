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


#: Inside benchmarks: sub-package → the benchmarks sub-packages it must not import.
FORBIDDEN_INSIDE = {
    "figures": ("benchmarks.experiments", "benchmarks.engine", "benchmarks.cli"),
    "engine": ("benchmarks.experiments", "benchmarks.figures", "benchmarks.cli"),
    "experiments": ("benchmarks.cli",),
}


def module_imports(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module
            yield from (f"{node.module}.{alias.name}" for alias in node.names)


@pytest.mark.parametrize("sub", list(FORBIDDEN_INSIDE))
def test_benchmarks_sub_packages_import_one_way(sub):
    for path in (ROOT / "benchmarks" / sub).rglob("*.py"):
        for name in module_imports(path):
            assert not name.startswith(FORBIDDEN_INSIDE[sub]), \
                f"{path.relative_to(ROOT)} imports {name}"


def test_benchmarks_top_level_stays_small():
    # Past about fifteen modules a flat folder stops explaining itself.
    modules = [p for p in (ROOT / "benchmarks").glob("*.py")]
    assert len(modules) <= 15, sorted(p.name for p in modules)


def test_benchmarks_top_level_modules_import_no_circle():
    """Imports between benchmarks/*.py, function-local ones included, form no circle."""
    modules = {p.stem: p for p in (ROOT / "benchmarks").glob("*.py") if p.stem != "__init__"}
    edges = {name: {other for other in modules if other != name and any(
        imported == f"benchmarks.{other}" or imported.startswith(f"benchmarks.{other}.")
        for imported in module_imports(path))} for name, path in modules.items()}

    def reaches(start, target, seen=()):
        return any(step == target or (step not in seen and reaches(step, target, seen + (step,)))
                   for step in edges[start])
    circles = sorted(name for name in modules if reaches(name, name))
    assert not circles, f"import circle through {circles}"


def test_no_module_imports_another_modules_private_name():
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            tree = ast.parse(path.read_text(), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module:
                    private = [a.name for a in node.names if a.name.startswith("_")
                               and not a.name.startswith("__")]
                    assert not private, f"{path.relative_to(ROOT)} imports {private} " \
                                        f"from {node.module}"


#: No function grows past what one can read at a glance.
MAX_FUNCTION_LINES = 100


def test_no_function_of_the_project_is_longer_than_a_screenful():
    long = []
    for package in PACKAGES + ("tests",):
        for path in (ROOT / package).rglob("*.py"):
            tree = ast.parse(path.read_text(), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    lines = node.end_lineno - node.lineno + 1
                    if lines > MAX_FUNCTION_LINES:
                        long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} "
                                    f"({lines} lines)")
    assert not long, f"longer than {MAX_FUNCTION_LINES} lines: {', '.join(long)}"
