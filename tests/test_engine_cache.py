"""The kernels' compiled cache follows every file they are compiled from
(numba alone follows only each function's own file)."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from benchmarks.engine import cache

ROOT = Path(cache.__file__).resolve().parents[2]


def _relative(files) -> set[str]:
    return {str(path.relative_to(ROOT)) for path in files}


def test_the_sources_hold_the_kernels_and_the_helpers_they_compile_in():
    sources = _relative(cache.kernel_sources())
    assert {str(p.relative_to(ROOT)) for p in (ROOT / "benchmarks/engine/kernels").glob("*.py")} \
        <= sources
    # Compiled into the kernels from outside their package: the MEKF's
    # transition coefficients, the IMU models, USQUE's state size, the GRP
    # constants, the complementary filters' steps.
    assert {"estimators/mekf.py", "estimators/imu/heading.py", "estimators/imu/gravity.py",
            "estimators/usque.py", "dynamics/quaternion.py",
            "estimators/complementary.py"} <= sources
    # Not what the kernels never see: the EKF's per-run class, the command line.
    assert not {"estimators/ekf.py", "benchmarks/cli.py"} & sources


def test_imports_are_read_across_lines_with_comments_and_aliases(tmp_path, monkeypatch):
    monkeypatch.setattr(cache, "_ROOT", tmp_path)
    for name in ("pkg_a", "pkg_b"):
        (tmp_path / "estimators" / name).mkdir(parents=True)
        (tmp_path / "estimators" / name / "__init__.py").write_text("")
    (tmp_path / "estimators" / "__init__.py").write_text("")
    (tmp_path / "estimators" / "pkg_a" / "deep.py").write_text("")
    module = tmp_path / "module.py"
    module.write_text("from estimators.pkg_a import (x,  # a comment\n    deep as d)\n"
                      "    import estimators.pkg_b\nimport numpy\n")
    assert cache._project_imports(module) == {"estimators.pkg_a", "estimators.pkg_a.deep",
                                              "estimators.pkg_b"}


def test_an_edited_source_changes_the_digest(tmp_path, monkeypatch):
    copy = tmp_path / "estimators" / "mekf.py"
    copy.parent.mkdir()
    shutil.copy(ROOT / "estimators/mekf.py", copy)
    monkeypatch.setattr(cache, "_ROOT", tmp_path)
    before = cache.sources_digest([copy])
    copy.write_text(copy.read_text() + "\n# edited\n")
    assert cache.sources_digest([copy]) != before


def _cache_dir(tmp_path) -> Path:
    directory = tmp_path / "__pycache__"
    directory.mkdir()
    for name in ("mekf.advance-1.py311.nbi", "mekf.advance-1.py311.1.nbc",
                 "other.f-3.py311.nbi"):
        (directory / name).write_bytes(b"compiled")
    return directory


def test_a_new_digest_removes_the_kernels_cached_code_and_only_theirs(tmp_path):
    directory = _cache_dir(tmp_path)
    assert cache.refresh(directory, "one", {"mekf"}) == 2
    assert sorted(p.name for p in directory.iterdir()) == [cache.DIGEST_FILE,
                                                          "other.f-3.py311.nbi"]
    assert (directory / cache.DIGEST_FILE).read_text().strip() == "one"


def test_the_same_digest_keeps_the_cached_code(tmp_path):
    directory = _cache_dir(tmp_path)
    cache.refresh(directory, "one", {"other"})
    (directory / "other.f-3.py311.nbi").write_bytes(b"compiled again")
    assert cache.refresh(directory, "one", {"mekf", "other"}) == 0
    assert (directory / "mekf.advance-1.py311.nbi").exists()
    assert (directory / "other.f-3.py311.nbi").read_bytes() == b"compiled again"


def test_a_cache_that_cannot_be_written_is_warned_of_not_fatal(monkeypatch):
    def refuse(*_):
        raise PermissionError("read-only")
    monkeypatch.setattr(cache, "refresh", refuse)
    monkeypatch.setattr(cache, "_checked", False)
    with pytest.warns(UserWarning, match="could not be checked"):
        cache.keep_fresh()
