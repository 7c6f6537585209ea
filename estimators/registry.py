"""The estimators by name, each class imported when it is first asked for.

The command line checks ``--estimators mekf,vqf`` and lists the names in its
help without importing filterpy, scipy or a peer library: the names and where
each class lives are this table's; :data:`ESTIMATORS` maps a name to its
class, importing that class's module on first use.
"""
from __future__ import annotations

import importlib
from collections.abc import Iterator, MutableMapping

from dynamics.validation import InvalidParameterError

#: Command-line name → ``module:Class`` (in :mod:`estimators`): the workshop's
#: three in the order it introduces them, then the flight filters. Adding an
#: estimator is one line here (its class's ``name`` is the key: a test keeps
#: them equal).
CATALOG = {
    "dead-reckoning": "dead_reckoning:DeadReckoning",
    "dead-reckoning-resets": "dead_reckoning_resets:DeadReckoningWithResets",
    "ekf": "ekf:QuaternionEKF",
    "mekf": "mekf:MultiplicativeEKF",
    "usque": "usque:USQUE",
    "mekf-smoother": "smoother:MekfSmoother",
    "triad": "static:TRIAD",
    "q-method": "static:DavenportQ",
    "quest": "static:QUEST",
    "esoq2": "static:ESOQ2",
    "foam": "static:FOAM",
    "svd": "static:SVD",
    "madgwick": "complementary:Madgwick",
    "madgwick-broad": "complementary:MadgwickBROAD",
    "mahony": "complementary:Mahony",
    "vqf": "peers:VQF9D",
    "vqf-6d": "peers:VQF6D",
    "vqf-offline": "peers:OfflineVQF",
    "fusion": "peers:Fusion",
}


class _Registry(MutableMapping):
    """Name → class, in :data:`CATALOG`'s order; ``name in ESTIMATORS`` and
    ``list(ESTIMATORS)`` import nothing, ``ESTIMATORS[name]`` its module. A
    class may also be registered at run time (``ESTIMATORS["mine"] = Mine``:
    a plug-in, a test's toy), after the catalogue's."""

    def __init__(self):
        self._added = {}

    def __getitem__(self, name: str) -> type:
        if name in self._added:
            return self._added[name]
        module, _, class_name = CATALOG[name].partition(":")
        return getattr(importlib.import_module(f"estimators.{module}"), class_name)

    def __setitem__(self, name: str, cls: type) -> None:
        self._added[name] = cls

    def __delitem__(self, name: str) -> None:
        del self._added[name]          # the catalogue's own stay: KeyError

    def __iter__(self) -> Iterator[str]:
        return iter({**dict.fromkeys(CATALOG), **dict.fromkeys(self._added)})

    def __len__(self) -> int:
        return len(set(CATALOG) | set(self._added))

    def __repr__(self) -> str:
        return f"ESTIMATORS({', '.join(self)})"


ESTIMATORS = _Registry()


def check_estimator_name(spec: str) -> str:
    """``spec`` if it names an estimator (a registry name, imported by
    nobody yet, or a user's class, imported and checked by
    :func:`resolve_estimator`); else :class:`InvalidParameterError`."""
    if spec not in ESTIMATORS:
        resolve_estimator(spec)
    return spec


#: What a concrete estimator must override: the base class's raise NotImplementedError.
ABSTRACT_METHODS = ("_step", "reset")


def resolve_estimator(spec: str) -> type:
    """The estimator class ``spec`` names: a registry name (``"mekf"``) or a
    user's own class as ``"package.module:ClassName"``, which must subclass
    :class:`estimators.AttitudeEstimator` and implement its
    :data:`ABSTRACT_METHODS` (its module importable: installed, or on
    ``PYTHONPATH``). Importing the module runs its code: callers reading a
    data file ask the user's consent first (:meth:`benchmarks.Scenario.from_toml`)."""
    if spec in ESTIMATORS:
        return ESTIMATORS[spec]
    rule = (f"must be one of {', '.join(ESTIMATORS)}, or package.module:ClassName for your "
            "own AttitudeEstimator subclass")
    module_name, colon, class_name = str(spec).partition(":")
    if not colon or not module_name or not class_name.isidentifier():
        raise InvalidParameterError("estimator", spec, rule)
    return _checked_class(spec, _imported(spec, module_name), class_name)


def _imported(spec: str, module_name: str):
    try:
        return importlib.import_module(module_name)
    except SystemExit as err:     # a module that ends the process on import: say so, go on
        raise InvalidParameterError("estimator", spec, f"cannot import {module_name}: it "
                                    f"calls sys.exit({err.code!r}) when imported") from None
    except Exception as err:      # the user's module: any import failure is reported
        raise InvalidParameterError("estimator", spec, f"cannot import {module_name} "
                                    f"({type(err).__name__}: {err})") from None


def _checked_class(spec: str, module, class_name: str) -> type:
    """``module``'s class ``class_name``, if it is a concrete estimator."""
    from estimators.base import AttitudeEstimator
    where = module.__name__
    if not hasattr(module, class_name):
        raise InvalidParameterError("estimator", spec, f"module {where} has no class {class_name}")
    cls = getattr(module, class_name)
    if not (isinstance(cls, type) and issubclass(cls, AttitudeEstimator)):
        raise InvalidParameterError("estimator", spec, f"{class_name} in {where} is not an "
                                    "estimator: it must be a subclass of "
                                    "estimators.AttitudeEstimator")
    missing = [method for method in ABSTRACT_METHODS
               if getattr(cls, method) is getattr(AttitudeEstimator, method)]
    if missing:
        raise InvalidParameterError("estimator", spec, f"{class_name} is abstract: it does "
                                    f"not implement {' and '.join(missing)}")
    return cls
