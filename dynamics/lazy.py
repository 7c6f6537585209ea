"""Packages that import their modules when a name is first asked for.

Importing ``estimators.base`` runs ``estimators/__init__.py`` first; were that
to import every estimator (and through them filterpy and scipy), the command
line would spend a second before it could answer ``--help``. So each package
of the project names, in its ``__init__``, the module each public name lives
in, and imports that module only when the name is first used (PEP 562's
module ``__getattr__``): ``from sensors import Gyro`` works as before.
"""
from __future__ import annotations

import importlib
import sys


def lazy_exports(package: str, modules: dict[str, tuple[str, ...]]):
    """``(__getattr__, __dir__, __all__)`` for ``package``, whose public
    names are ``modules``' values, each exported by the module (relative to
    the package) that is its key."""
    home = {name: module for module, names in modules.items() for name in names}

    def __getattr__(name: str):
        if name not in home:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{home[name]}"), name)
        setattr(sys.modules[package], name, value)      # asked once, imported once
        return value

    def __dir__() -> list[str]:
        return sorted(set(home) | set(vars(sys.modules[package])))

    return __getattr__, __dir__, sorted(home)
