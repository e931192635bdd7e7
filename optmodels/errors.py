"""The package's exceptions: one base class, :class:`OptModelsError`, and its three kinds.

:class:`ProblemError` (bad input: a ``ValueError`` too), :class:`SolverNotAvailable` (an
``ImportError`` too) and :class:`SolveError` (a ``RuntimeError`` too). Re-exported by
:mod:`optmodels.core`, where the rest of the package imports them from.
"""

from __future__ import annotations

from typing import Any

__all__ = ["OptModelsError", "ProblemError", "SolveError", "SolverNotAvailable"]


class OptModelsError(Exception):
    """Base class of every exception raised by optmodels."""


class ProblemError(OptModelsError, ValueError):
    """Bad input: wrong shape, non-finite values, a covariance that is not SPD,
    degenerate geometry, too few points, an infeasible specification."""


class SolverNotAvailable(OptModelsError, ImportError):
    """The requested solver is not installed; the message carries the install hint."""


class SolveError(OptModelsError, RuntimeError):
    """The solver failed and the caller asked for a solution (``Solution.require_ok``)."""

    def __init__(self, message: str, solution: Any = None) -> None:
        super().__init__(message)
        self.solution = solution
