"""optmodels: radar estimation problems written as optimization models.

Each problem module writes the paper's problem in its original constrained form, solves
it generically (CVXPY, CasADi/IPOPT) and cross-checks it against the paper's closed form.
"""

from optmodels import fusion, plane, trajectories
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
    "fusion",
    "plane",
    "trajectories",
]
