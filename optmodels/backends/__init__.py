"""Solver back-ends: turn a CVXPY problem or a CasADi NLP into the common result fields."""

from optmodels.backends.common import BackendResult

__all__ = ["BackendResult"]
