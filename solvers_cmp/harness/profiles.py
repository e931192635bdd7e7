"""Settings profiles of the comparison harness and the success judgement of a row.

:class:`Profile` (solver options from the back-end's profile table, the success
tolerances, the per-run time limit), :data:`PROFILES` (``default``, ``high``) and
:func:`_judge`: ``success`` = status OK and ``solution_error`` ≤ the profile's
``error_tol`` and ``max_violation`` ≤ its ``violation_tol`` (qpbenchmark's definition),
``reason`` saying why not.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from optmodels.backends.profiles import profile_options


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
