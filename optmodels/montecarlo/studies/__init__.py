"""The built-in Monte Carlo studies, one module per paper (:data:`STUDIES`, :func:`study`).

A study is a picklable callable ``study(rng) -> dict[str, float]`` (here frozen dataclasses,
their parameters checked when built), optionally with ``summarise(values)``. Each imports
its problem package inside the trial, so that a worker process loads only what it runs.
Plane angle error vs the CRB (000), trajectories η vs Monte Carlo (002), Cov(vec Ŵ) vs (10)
(003), bias-field recovery error (001), association rate vs separation (004).

Modules: ``studies/<problem>.py`` for each registered problem that has a study (found by
:func:`_declared` through :func:`optmodels.registry.face_module`, no list to edit):
:mod:`~optmodels.montecarlo.studies.plane` (:class:`PlaneAngle`),
:mod:`~optmodels.montecarlo.studies.trajectories` (:class:`TrajectoriesEta`),
:mod:`~optmodels.montecarlo.studies.fusion` (:class:`FusionWeight`),
:mod:`~optmodels.montecarlo.studies.biasfield` (:class:`BiasfieldRecovery`),
:mod:`~optmodels.montecarlo.studies.assignment` (:class:`AssignmentSeparation`), and
:mod:`~optmodels.montecarlo.studies._common` (``_set``, shared by the classes). Every
study class is importable from here. They pickle under their module
(``optmodels.montecarlo.studies.plane.PlaneAngle``); a pickle written before the split
(``optmodels.montecarlo.studies.PlaneAngle``) still loads through the re-exports, and a
checkpoint's header holds only the class name and parameters.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import fields
from typing import Any

import numpy as np

from optmodels.core import ProblemError

# the five study classes, importable from here as before the split (so pickles written
# before it load too); a new problem's study needs no line here: STUDIES finds it
from optmodels.montecarlo.studies.assignment import AssignmentSeparation
from optmodels.montecarlo.studies.biasfield import BiasfieldRecovery
from optmodels.montecarlo.studies.fusion import FusionWeight
from optmodels.montecarlo.studies.plane import PlaneAngle
from optmodels.montecarlo.studies.trajectories import TrajectoriesEta

__all__ = [
    "STUDIES",
    "AssignmentSeparation",
    "BiasfieldRecovery",
    "FusionWeight",
    "PlaneAngle",
    "Study",
    "TrajectoriesEta",
    "study",
]


Study = Callable[[np.random.Generator], Mapping[str, float]]


def _declared() -> dict[str, Callable[..., Study]]:
    """The studies of the modules ``studies/<problem>.py``, one looked up per name of
    :func:`optmodels.registry.names` (a problem without one has no study), each class
    declaring its ``name`` and ``problem`` (class attributes), in the order of
    :mod:`optmodels.registry` (then by name): a new problem's study is its module here,
    no list to edit."""
    from optmodels import registry

    order = {p: i for i, p in enumerate(registry.names())}
    found = []
    for problem in registry.names():
        mod = registry.face_module(__name__, problem)
        if mod is None:
            continue
        found += [
            c
            for c in vars(mod).values()
            if isinstance(c, type)
            and c.__module__ == mod.__name__
            and isinstance(c.__dict__.get("name"), str)
            and "problem" in c.__dict__
        ]
    found.sort(key=lambda c: (order.get(c.__dict__["problem"], len(order)), c.__dict__["name"]))
    return {c.__dict__["name"]: c for c in found}


#: Built-in studies by name (the CLI's ``optmodels montecarlo NAME``): every study class
#: of the per-problem modules (:func:`_declared`).
STUDIES: dict[str, Callable[..., Study]] = _declared()


def study(name: str, **params: Any) -> Study:
    """A built-in study by name, e.g. ``study("plane-angle", n=100)``."""
    return _builtin(name, params)


def _builtin(name: str, params: Any) -> Study:
    if not isinstance(name, str) or name not in STUDIES:
        raise ProblemError(
            f"montecarlo.run study: unknown study {name!r} (built-in: {sorted(STUDIES)})"
        )
    if not isinstance(params, Mapping) or not all(isinstance(k, str) for k in params):
        raise ProblemError(
            f"montecarlo.run params: expected a mapping of parameter "
            f"names to values, got {type(params).__name__}"
        )
    cls = STUDIES[name]
    known = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ProblemError(
            f"montecarlo.run params: unknown parameter(s) {unknown} of "
            f"study {name!r} (it takes {known})"
        )
    return cls(**params)
