"""The folders tell the story: imports point one way between the packages."""
import ast
from pathlib import Path

import pytest

from tests.conftest import source_tree

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
    tree = source_tree(path)
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
    "figures": ("benchmarks.experiments", "benchmarks.engine", "benchmarks.cli",
                "benchmarks.commands"),
    "engine": ("benchmarks.experiments", "benchmarks.figures", "benchmarks.cli",
               "benchmarks.commands"),
    "experiments": ("benchmarks.cli", "benchmarks.commands"),
    "broad": ("benchmarks.cli", "benchmarks.commands"),
}


def module_imports(path):
    tree = source_tree(path)
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


def project_modules() -> dict:
    """Every module of the project's packages, by its dotted name (a
    package by its own: ``estimators`` for ``estimators/__init__.py``)."""
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def import_edges(modules: dict) -> dict:
    """module → the project modules it imports, function-local imports
    included; ``from package import name`` points at ``package.name`` where
    that is a module, else at the package."""
    def module_of(name):
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name
    edges = {}
    for name, path in modules.items():
        tree = source_tree(path)
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                imported.update(module_of(alias.name) for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                imported.update(module_of(f"{node.module}.{alias.name}") for alias in node.names)
        edges[name] = imported - {"", name}
    return edges


def circles(edges: dict) -> list:
    """The import circles of ``edges``: each strongly connected set of more
    than one module (Tarjan's algorithm, iterative), sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            step = next(successors, None)
            if step is not None:
                if step not in index:
                    index[step] = low[step] = len(index)
                    stack.append(step)
                    on_stack.add(step)
                    work.append((step, iter(sorted(edges.get(step, ())))))
                elif step in on_stack:
                    low[node] = min(low[node], index[step])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                members = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    members.append(member)
                    if member == node:
                        break
                if len(members) > 1:
                    found.append(sorted(members))
    return sorted(found)


def test_the_circle_finder_finds_a_circle_and_only_a_circle():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": {"c"}, "c": set(), "d": {"a", "c"}}) == []


def test_no_import_circle_anywhere_in_the_project():
    """Imports between the project's modules, function-local ones included,
    form no circle: each module can be read before the ones that use it."""
    found = circles(import_edges(project_modules()))
    assert not found, f"import circles: {found}"


def test_no_module_imports_another_modules_private_name():
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            tree = source_tree(path)
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module:
                    private = [a.name for a in node.names if a.name.startswith("_")
                               and not a.name.startswith("__")]
                    assert not private, f"{path.relative_to(ROOT)} imports {private} " \
                                        f"from {node.module}"


#: No function grows past what one can read at a glance (issue 31).
MAX_FUNCTION_LINES = 60
#: No module or class of the project grows past what one can hold in mind.
MAX_MODULE_LINES = 500
MAX_CLASS_LINES = 200


def _definitions(root, packages, kinds):
    """``(where, lines)`` of every definition of ``kinds`` in ``packages`` under ``root``."""
    for package in packages:
        for path in (root / package).rglob("*.py"):
            tree = source_tree(path)
            for node in ast.walk(tree):
                if isinstance(node, kinds):
                    yield (f"{path.relative_to(root).as_posix()}:{node.name}",
                           node.end_lineno - node.lineno + 1)


def long_functions(root, packages) -> list:
    kinds = (ast.FunctionDef, ast.AsyncFunctionDef)
    return [f"{name} ({lines} lines)" for name, lines in _definitions(root, packages, kinds)
            if lines > MAX_FUNCTION_LINES]


def long_classes(root, packages) -> list:
    return [f"{name} ({lines} lines)" for name, lines in
            _definitions(root, packages, ast.ClassDef) if lines > MAX_CLASS_LINES]


def long_modules(root, packages) -> list:
    return [f"{path.relative_to(root).as_posix()} ({count} lines)" for package in packages
            for path in (root / package).rglob("*.py")
            if (count := len(path.read_text().splitlines())) > MAX_MODULE_LINES]


def test_no_function_of_the_project_is_longer_than_a_screenful():
    long = long_functions(ROOT, PACKAGES + ("tests",))
    assert not long, f"longer than {MAX_FUNCTION_LINES} lines: {', '.join(long)}"


def test_no_class_of_the_project_is_longer_than_a_few_screens():
    long = long_classes(ROOT, PACKAGES)
    assert not long, f"longer than {MAX_CLASS_LINES} lines: {', '.join(long)}"


def test_no_module_of_the_project_is_longer_than_it_can_be_read():
    long = long_modules(ROOT, PACKAGES)
    assert not long, f"longer than {MAX_MODULE_LINES} lines: {', '.join(long)}"


def test_the_size_checks_find_what_is_too_long(tmp_path):
    statements = "".join(f"        x{i} = {i}\n" for i in range(MAX_CLASS_LINES))
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "big.py").write_text(
        "class Big:\n    def f(self):\n" + statements + "\n" * MAX_MODULE_LINES +
        "def g():\n" + "    pass\n" * (MAX_FUNCTION_LINES - 1))
    assert long_functions(tmp_path, ("pkg",)) == [f"pkg/big.py:f ({MAX_CLASS_LINES + 1} lines)"]
    assert long_classes(tmp_path, ("pkg",)) == [f"pkg/big.py:Big ({MAX_CLASS_LINES + 2} lines)"]
    assert long_modules(tmp_path, ("pkg",)) == [
        f"pkg/big.py ({2 + MAX_CLASS_LINES + MAX_MODULE_LINES + MAX_FUNCTION_LINES} lines)"]


def test_the_readmes_key_reference_is_the_generated_one():
    # The README's tables of every scenario and recording key are
    # show-config --keys's output, made from the one declaration of each.
    from benchmarks.experiments.configuration import key_reference
    text = (ROOT / "README.md").read_text()
    copy = text.split("<!-- keys -->\n", 1)[1].split("<!-- /keys -->", 1)[0]
    assert copy == key_reference()


def test_show_config_keys_prints_the_reference(capsys):
    from benchmarks.cli import main
    from benchmarks.experiments.configuration import key_reference
    assert main(["show-config", "--keys"]) == 0
    assert capsys.readouterr().out == key_reference()
