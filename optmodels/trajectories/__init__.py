r"""Least-squares estimation of dependent linear trajectories (paper 002, Simonova).

Paper: ``shared/papers/002_7b4fdec12ab33196.txt``, equations (1)-(20).

Problem as posed
----------------
Object :math:`j = 1..Q` moves along the line :math:`y_j(t) = y_{0j} + V_j t` and is measured
:math:`N_j` times, :math:`y_{ji} = y_{0j} + V_j t_{ji} + \Delta y_{ji}`, with independent
errors :math:`\Delta y \sim N(0, \sigma^2)` (classified sample: every measurement is known
to belong to its object). Least squares (1):

.. math::
    W = \sum_j \sum_i w_{ji}\,(y_{ji} - y_{0j} - V_j t_{ji})^2 \to \min,
    \qquad w_{ji} = 1/\sigma_{ji}^2

over the ``2Q`` parameters of ``Q`` lines, **subject to** the equality constraints of the
family:

* diverging (РТ): :math:`y_{01} = \dots = y_{0Q}`, :math:`\theta = (y_0, V_1..V_Q)` (4)-(5);
* parallel (ПТ): :math:`V_1 = \dots = V_Q`, :math:`\theta = (y_{01}..y_{0Q}, V)` (10)-(11);
* independent: no constraint, :math:`\theta = (y_{01}..y_{0Q}, V_1..V_Q)`;
* any :class:`Family` of shared starts and shared velocities (objects 1-3 share a start,
  4-5 share a velocity, ...).

The paper writes ``W`` in the constrained parameters directly: :math:`W = \|Y - A\theta\|^2`
with the design matrix ``A`` (2), (5), (11), whose solution is (3)
:math:`\hat\theta = (A^TA)^{-1}A^TY` with covariance (14) :math:`\Psi = \sigma^2(A^TA)^{-1}`.
Values may be vectors (``d = 2`` or ``3`` coordinates with the same dependence): each
coordinate is its own problem with the same ``A``.

Entry points
------------
:func:`solve` (CVXPY: the ``Q`` lines with the family's equality constraints,
``formulation="constrained"``, or the unconstrained problem in θ, ``"reduced"``),
:func:`closed_form` (the paper's route: (8)-(9) diverging, (12)-(13) parallel; the normal
equations (3) for other families), :func:`covariance` (Ψ (14) from the design matrix),
:func:`paper_covariance` ((16)-(20), printed and corrected), :func:`variance_ratios`,
:func:`eta` / :func:`eta0` (the conclusions' ratios for any ``Q`` and ``N``),
:func:`independent_variances` (the introduction's single-line values),
:func:`family_test` (does a dependent family fit as well as independent lines?).

Numerics (clock origin, conditioning)
------------------------------------
Estimates do not depend on the clock's origin. Every fit works in per-object centred
times: object j's line is first written as its position at its own weighted mean time
T_j and its velocity, from the centred moments Σw, Σw(t − T_j)², Σw(t − T_j)(y − ȳ_j);
the paper's sums (8)-(9), (12)-(13) are those moments recombined without the cancellation
that loses (|t − epoch| / spread)² digits (POSIX times: 14 of 16). The start at ``epoch``
is obtained last, as the extrapolation ``p_j − (T_j − epoch)·V_j``, and Ψ is transformed
with it. Every answer, closed form or generic, ends in a re-check against the original
problem: the exact distance to the least-squares optimum (one Newton step of the
quadratic, Ψ·∇W, computed in the centred coordinates) relative to the size of each
parameter (or its standard deviation if larger), the "stationarity" residual; with
:func:`optmodels.core.verified_status` (closed forms) or :func:`solve`'s stricter rule.
Data whose float64 times cannot resolve an object's spread (``eps·|t| / std(t)`` above
1e-3) are refused as numerically singular; above 1e-6, and when the epoch is so far from
the data that the reported start cannot carry the line to 1 % of its standard deviation
(``eps·|V_j (T_j − epoch)| ·√Σw > 0.01``), the status is downgraded to
OPTIMAL_INACCURATE; beyond one standard deviation ``epoch`` is refused.

Errata (details and tests in ``docs/errata.md``)
------------------------------------------------
* (13): ``E`` is printed :math:`\sum_j\sum_i t_{ji}`; it is :math:`\sum_j\sum_i t_{ji}^2`.
* (18) and (20) are printed without the inverse in the first equality; (18) drops
  :math:`\sigma^2` in the second; in (18) the elements (2,1), (3,1) have the wrong sign and
  (2,3), (3,2) are wrong; in (20) the element (1,2) is wrong (see :func:`paper_covariance`).
* "Ψ does not depend on the time origin" (before (17)) is false: :math:`y_0` is the position
  at ``t = 0`` and the diverging family's common start *is* the instant ``t = 0``. (16)-(20)
  and the ratios hold for :math:`t_i = (i-1)\Delta T`, i.e. the first measurement at the
  common start.
* The introduction's "СКО" :math:`2(2N-1)/(N(N+1))` and :math:`12/(N(N^2-1)T_0^2)` are
  **variances in units of** :math:`\sigma^2`; the conclusions' η, η0 are ratios of
  variances (the RMS ratio is √η), for ``Q = 2``; for ``Q`` objects η0 = 1/Q and
  η = 1 - r(1 - 1/Q), r = 3(N-1)/(2(2N-1)).
Package layout
--------------
``data`` (:class:`TrajectoryData`, :class:`Family`, :func:`resolve_family`), ``moments``
(the per-object centred moments, the time-resolution refusal), ``original`` (the original
problem in NumPy: :func:`predict`, :func:`objective`, :func:`constraint_residuals`,
:func:`design_matrix`), ``fits`` (the closed-form algebra (8)-(9), (12)-(13), (3) and Ψ),
``verify`` (the re-check, the downgrade rules and the gate), ``solution``
(:class:`TrajectorySolution`), ``generic`` (:func:`solve`), ``closedform``
(:func:`closed_form`), ``covariances`` (Ψ (14)-(20), η, η0), ``model_choice``
(:func:`family_test`). Every public name is re-exported here; import from
``optmodels.trajectories``.
"""

# Also importable, outside ``__all__`` as before: the documented constants, the family-name
# type and resolve_family. ``X as X`` marks a re-export.
from optmodels.trajectories.closedform import closed_form
from optmodels.trajectories.covariances import (
    covariance,
    eta,
    eta0,
    independent_variances,
    paper_covariance,
    variance_ratios,
)
from optmodels.trajectories.data import FAMILIES, Family, TrajectoryData
from optmodels.trajectories.data import FamilyName as FamilyName
from optmodels.trajectories.data import resolve_family as resolve_family
from optmodels.trajectories.generic import SOLVER_DEFAULTS as SOLVER_DEFAULTS
from optmodels.trajectories.generic import solve
from optmodels.trajectories.model_choice import FamilyTest, family_test
from optmodels.trajectories.moments import EPS as EPS
from optmodels.trajectories.moments import TIME_RESOLUTION_MAX as TIME_RESOLUTION_MAX
from optmodels.trajectories.moments import TIME_RESOLUTION_WARN as TIME_RESOLUTION_WARN
from optmodels.trajectories.original import (
    constraint_residuals,
    design_matrix,
    objective,
    predict,
)
from optmodels.trajectories.solution import TrajectorySolution
from optmodels.trajectories.verify import EXTRAPOLATION_MAX as EXTRAPOLATION_MAX
from optmodels.trajectories.verify import EXTRAPOLATION_WARN as EXTRAPOLATION_WARN
from optmodels.trajectories.verify import REJECT_TOL as REJECT_TOL
from optmodels.trajectories.verify import VERIFY_TOL as VERIFY_TOL

__all__ = [
    "FAMILIES",
    "Family",
    "FamilyTest",
    "TrajectoryData",
    "TrajectorySolution",
    "closed_form",
    "constraint_residuals",
    "covariance",
    "design_matrix",
    "eta",
    "eta0",
    "family_test",
    "independent_variances",
    "objective",
    "paper_covariance",
    "predict",
    "solve",
    "variance_ratios",
]
