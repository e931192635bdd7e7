"""Solver back-ends: turn a CVXPY problem or a CasADi NLP into the common result fields, and
own what the problems need to know about solvers.

- :mod:`~optmodels.backends.cvxpy_backend`: ``solve_problem`` and its status table, the
  MILP solvers and their banner silencing;
- :mod:`~optmodels.backends.casadi_backend`: CasADi ``nlpsol`` plugins (build, run, status
  tables, option defaults);
- :mod:`~optmodels.backends.casadi_qp`: CasADi ``conic`` plugins as CVXPY solvers (their
  status table :data:`~optmodels.backends.casadi_qp.CONIC_STATUS`);
- :mod:`~optmodels.backends.profiles`: option defaults per problem class (``lsq``, ``qp``,
  ``socp``), the settings profiles (``default``, ``high``) and the MILP gap/time-limit names.
"""

from optmodels.backends.common import BackendResult

__all__ = ["BackendResult"]
