"""Settings profiles of the comparison harness and the success judgement of a row.

:class:`Profile` (solver options from the back-end's profile table, the success
tolerances, the per-run time limit), :data:`PROFILES` (``default``, ``high``) and
:func:`_judge`: ``success`` = status OK and ``solution_error`` ≤ the profile's
``error_tol`` and ``max_violation`` ≤ its ``violation_tol`` (qpbenchmark's definition),
``reason`` saying why not.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from optmodels.backends.profiles import DEFAULTS, profile_options


@dataclass(frozen=True)
class Profile:
    """A settings profile: solver options and the success tolerances.

    ``error_tol`` bounds ``solution_error`` (relative, or radians for the plane normal;
    assignment errors are 0/1), ``violation_tol`` the re-computed residuals of the
    original problem; ``time_limit`` (s) is per run, and is what a failure is charged in
    the shifted geometric means.
    """

    name: str
    error_tol: float
    violation_tol: float
    time_limit: float
    high_accuracy: bool

    def options(self, solver: str) -> dict[str, Any]:
        """Solver options for this profile, from the back-end's profile table
        (:data:`optmodels.backends.profiles.PROFILES`): none for ``default`` (the
        package's defaults), :data:`~optmodels.backends.profiles.HIGH_OPTIONS` for
        ``high``."""
        return profile_options("high" if self.high_accuracy else "default", solver)


PROFILES: dict[str, Profile] = {
    # optmodels' own solver defaults (already tighter than several solvers' own); success
    # at 1e-5: what a tracking engineer needs (sub-metre on 100 km, sub-μrad on angles).
    "default": Profile("default", 1e-5, 1e-6, 60.0, False),
    # every solver pushed to ~1e-10: who reaches 1e-8 at all, and at what cost.
    "high": Profile("high", 1e-8, 1e-8, 120.0, True),
}


def _judge(row: dict[str, Any], prof: Profile) -> None:
    ok = row.pop("ok", False)
    err, viol = row["solution_error"], row["max_violation"]
    reasons = []
    if not ok:
        reasons.append(f"status {row['status']}")
    elif not np.isfinite(err):
        reasons.append("no solution error (reference failed)")
    else:
        if err > prof.error_tol:
            reasons.append(f"solution error {err:.1e} > {prof.error_tol:.0e}")
        if not np.isfinite(viol) or viol > prof.violation_tol:
            reasons.append(f"violation {viol:.1e} > {prof.violation_tol:.0e}")
    row["success"] = not reasons
    row["reason"] = "; ".join(reasons)


def options_key(prof: Profile, solver: str) -> str:
    """The ``options`` column (part of the resume key): JSON of what can reach ``solver``
    -- the profile's options and the back-end's class defaults for it
    (:data:`optmodels.backends.profiles.DEFAULTS`) -- so that a change of either
    recomputes the rows instead of reusing them."""
    up = solver.upper()
    doc = {
        "profile": prof.options(solver),
        "defaults": {c: t[up] for c, t in DEFAULTS.items() if up in t},
    }
    return json.dumps(doc, sort_keys=True, separators=(",", ":"), default=str)


#: Runs the quick sweep (``run_sweep(skip_slow=True)``, the demo's comparison) leaves
#: out: (problem, solver, formulation or None, instance or None) → (smallest size
#: skipped, measured reason). Measured in issue 27's quick sweep (5 s limit, 2 cores
#: shared): each of these runs sat at the time limit, 18 runs = 90 s of the 151 s
#: comparison. A full ``optmodels compare`` runs them all.
TOO_SLOW: dict[tuple[str, str, str | None, str | None], tuple[int, str]] = {
    ("trajectories", "CASADI_QPOASES", None, None): (
        100,
        "dense active set: > 5 s at Q = 10 × 100 points (1000-variable QP)",
    ),
    ("fusion", "CASADI_QPOASES", "min-trace W", None): (
        20,
        "dense active set: > 5 s on the m = 20 minimum-trace QP",
    ),
    ("biasfield", "CASADI_QPOASES", None, None): (
        100,
        "dense active set: > 5 s from K = 100 cells",
    ),
    ("biasfield", "CASADI_DAQP", None, None): (
        500,
        "> 5 s from K = 500 cells (and fails the singular sum_squares Hessian)",
    ),
    ("biasfield", "CASADI_QRQP", "constrained", "box"): (
        100,
        "> 5 s on the constrained box QP from K = 100",
    ),
    ("biasfield", "CASADI_PROXQP", "constrained", "box"): (
        500,
        "> 5 s on the constrained box QP from K = 500",
    ),
    ("biasfield", "OSQP", "constrained", "box"): (
        100,
        "> 5 s on the constrained box QP from K = 100 at eps 1e-6 as at 1e-9 (ADMM "
        "converges slowly once bounds bind; the reduced form solves)",
    ),
    ("biasfield", "CASADI_OSQP", "constrained", "box"): (
        100,
        "as OSQP through CVXPY: > 5 s on the constrained box QP from K = 100",
    ),
    ("plane", "feasiblesqpmethod", "full", "radar"): (
        100,
        "> 5 s on the full NLP with general covariances from N = 100",
    ),
}


def too_slow(case: Any, run: Any) -> str | None:
    """Why the quick sweep leaves ``run`` on ``case`` out (:data:`TOO_SLOW`), or None."""
    for (problem, solver, form, inst), (size, why) in TOO_SLOW.items():
        if (
            case.problem == problem
            and run.solver == solver
            and form in (None, run.formulation)
            and inst in (None, case.instance)
            and case.size >= size
        ):
            return why
    return None
