"""optmodels: radar estimation problems written as optimization models.

Each problem module writes the paper's problem in its original constrained form, solves
it generically (CVXPY, CasADi/IPOPT) and cross-checks it against the paper's closed form.

The problems are the packages registered in :mod:`optmodels.registry`; each is imported
on first use (``from optmodels import plane`` or ``optmodels.plane``), so that ``import
optmodels`` stays cheap. ``__all__`` lists them after the core names.
"""

from __future__ import annotations

import importlib
from typing import Any

from optmodels import registry as _registry
from optmodels.core import (
    OptModelsError,
    ProblemError,
    Solution,
    SolveError,
    SolverNotAvailable,
    Status,
)

__version__ = "0.1.0"

__all__ = [
    "OptModelsError",
    "ProblemError",
    "Solution",
    "SolveError",
    "SolverNotAvailable",
    "Status",
]
__all__ += sorted(_registry.names())  # the registered problems (lazy, see __getattr__)


def __getattr__(name: str) -> Any:
    """A registered problem's package, imported on first access."""
    if name in _registry.names():
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_registry.names()))
