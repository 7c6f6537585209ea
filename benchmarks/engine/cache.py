"""The kernels' compiled cache, kept true to their sources.

numba keys a compiled function's cache to its own file (its time stamp and
size): a kernel that inlines a helper from another file, or compiles in a
constant of another module (``estimators.usque.STATE_SIZE``), is read back
from the cache unchanged after that file is edited — the engine would then
run the old code beside a per-run class that runs the new. So the engine
keeps a digest of every file its kernels are compiled from (the kernels'
package and the project modules they import, followed through their own
imports: :func:`kernel_sources`) beside the cache, and where the digest
differs it removes the kernels' cached code, which then compiles anew
(:func:`keep_fresh`, once per process, before the first kernel is loaded).
"""
from __future__ import annotations

import hashlib
import re
import warnings
from pathlib import Path

#: The project's top-level packages: imports of these are followed.
PROJECT_PACKAGES = ("benchmarks", "dynamics", "estimators", "sensors")
#: The file beside the cache holding the digest of the sources it was compiled from.
DIGEST_FILE = "kernel-sources.sha256"

_ROOT = Path(__file__).resolve().parents[2]
_KERNELS = Path(__file__).resolve().parent / "kernels"
_checked = False
#: ``from MODULE import NAMES`` (NAMES in parentheses across lines, or to the
#: line's end) or ``import PLAIN``, at any indentation.
_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+(?P<module>[\w.]+)[ \t]+import[ \t]+"
                     r"(?P<names>\([^)]*\)|[^\n#]*)|import[ \t]+(?P<plain>[\w., \t]+))",
                     re.MULTILINE)


def _module_file(name: str) -> Path | None:
    """The project file of module ``name`` (a package's ``__init__.py``), or None."""
    path = _ROOT.joinpath(*name.split("."))
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def _project_imports(path: Path) -> set[str]:
    """The project modules that the file ``path`` imports (``from a.b import c``
    names ``a.b``, and ``a.b.c`` where ``c`` is a module). Read with a
    pattern, not parsed: parsing the 37 files took a sixth of a second."""
    found = set()
    for match in _IMPORT.finditer(path.read_text(encoding="utf-8")):
        module, names, plain = match.group("module"), match.group("names"), match.group("plain")
        if plain is not None:
            candidates = [name.split(" as ")[0].strip() for name in plain.split(",")]
        else:
            names = re.sub(r"#[^\n]*", "", names).strip("()")
            candidates = [module] + [f"{module}.{name.split(' as ')[0].strip()}"
                                     for name in names.split(",") if name.strip()]
        found.update(name for name in candidates
                     if name.split(".")[0] in PROJECT_PACKAGES and _module_file(name))
    return found


def kernel_sources() -> list[Path]:
    """Every file the kernels are compiled from: the kernels' package and the
    project modules it imports, and theirs, in a fixed order."""
    files = set(_KERNELS.glob("*.py"))
    pending = [module for path in files for module in _project_imports(path)]
    while pending:
        path = _module_file(pending.pop())
        if path is not None and path not in files:
            files.add(path)
            pending.extend(_project_imports(path))
    return sorted(files)


def sources_digest(files) -> str:
    """SHA-256 of the files' paths (relative to the project) and contents."""
    digest = hashlib.sha256()
    for path in files:
        digest.update(str(Path(path).resolve().relative_to(_ROOT)).encode())
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()


def refresh(cache_dir: Path, digest: str, modules) -> int:
    """Remove the cached code of ``modules`` (file stems) from ``cache_dir``
    unless its recorded digest is ``digest``; record ``digest``. Returns the
    number of files removed."""
    cache_dir = Path(cache_dir)
    record = cache_dir / DIGEST_FILE
    if record.is_file() and record.read_text().strip() == digest:
        return 0
    removed = 0
    for path in cache_dir.glob("*.nb[ic]"):
        if path.name.split(".")[0] in modules:
            path.unlink(missing_ok=True)    # another process may have removed it
            removed += 1
    cache_dir.mkdir(parents=True, exist_ok=True)
    record.write_text(digest + "\n")
    return removed


def keep_fresh() -> None:
    """:func:`refresh` the kernels' cache against their sources, once per process
    (numba reads a removed file as a cache miss, so processes racing here
    only compile again)."""
    global _checked
    if _checked:
        return
    _checked = True
    from benchmarks.engine.kernels import common
    cache_dir = getattr(getattr(common.record_error, "_cache", None), "_cache_path", None)
    if cache_dir is None:       # caching off (NUMBA_DISABLE_JIT): nothing to keep
        return
    try:
        refresh(Path(cache_dir), sources_digest(kernel_sources()),
                {path.stem for path in _KERNELS.glob("*.py")})
    except OSError as err:      # a cache numba may read but this user may not write
        warnings.warn(f"the kernels' cache in {cache_dir} could not be checked against "
                      f"their sources ({err}); if a kernel's helper was edited since it "
                      "was compiled, remove that cache's *.nbi and *.nbc files")
