"""The paper's closed forms as a solution (paper 002): :func:`closed_form` -- diverging
(8)-(9), parallel (12)-(13) (optionally as misprinted), single-line LSQ, the normal
equations (3) of any other family -- re-checked against the original problem with
:func:`optmodels.core.verified_status`. The algebra itself is in :mod:`.fits`.

(Named ``closedform``, as in every problem package, so that the module does not shadow the function
``optmodels.trajectories.closed_form``.)
"""

from __future__ import annotations

from typing import Any

from optmodels.core import ProblemError, Status, Verdict, as_flag, as_instance, timed
from optmodels.trajectories.data import Family, FamilyName, TrajectoryData, resolve_family
from optmodels.trajectories.fits import _fit, _kind
from optmodels.trajectories.solution import TrajectorySolution
from optmodels.trajectories.verify import REJECT_TOL, VERIFY_TOL, _finish, _recheck


# --------------------------------------------------------------------------- closed forms
def closed_form(
    data: TrajectoryData, family: FamilyName | Family = "diverging", *, printed: bool = False
) -> TrajectorySolution:
    """The paper's closed forms, in its own notation (weighted sums where variances differ).

    * diverging (8)-(9): :math:`y_0 = (D - A_C)/(E - B_C)`, :math:`V_j = (A_j - y_0B_j)/C_j`
      with :math:`D = \\sum y`, :math:`E = \\sum N_j`, :math:`A_j = \\sum_i y t`,
      :math:`B_j = \\sum_i t`, :math:`C_j = \\sum_i t^2`, :math:`A_C = \\sum_j A_jB_j/C_j`,
      :math:`B_C = \\sum_j B_j^2/C_j`;
    * parallel (12)-(13): :math:`V = (D - A_N)/(E - B_N)`,
      :math:`y_{0j} = (A_j - VB_j)/N_j` with :math:`D = \\sum y t`, :math:`A_j = \\sum_i y`,
      :math:`B_j = \\sum_i t`, :math:`A_N = \\sum_j A_jB_j/N_j`, :math:`B_N = \\sum_j B_j^2/N_j`
      and :math:`E = \\sum t^2` (printed: :math:`\\sum t`, erratum; ``printed=True``
      reproduces it);
    * independent: the single-line formulas per object; any other :class:`Family`: the
      normal equations (3).

    Here t is ``t − epoch``. The differences D − A_C, E − B_C, D − A_N, E − B_N are
    evaluated from per-object centred moments (see the module notes), which is the same
    algebra without its cancellation. Ψ is computed along the same route (Schur complements
    of the block-diagonal part), so that it can be checked against the design matrix.

    The answer is re-checked against the original problem
    (:func:`optmodels.core.verified_status` on the equalities and the stationarity): an
    answer that cannot be trusted is OPTIMAL_INACCURATE, or ERROR with NaN estimates (the
    rejected θ in ``info["rejected_theta"]``). ``printed=True`` returns the misprinted (13)'s
    numbers with status ERROR: they are not the least-squares optimum.

    Raises
    ------
    ProblemError
        Bad arguments, a numerically singular design, an epoch too far from the data.
    """
    as_instance("trajectories.closed_form data", data, TrajectoryData)
    fam = resolve_family(family, data.n_objects)
    as_flag("trajectories.closed_form printed", printed)
    with timed() as tm:
        kind = _kind(fam)
        if printed and kind != "parallel":
            raise ProblemError("printed: only the parallel family (13) has a misprint")
        fit = _fit(data, fam, printed=bool(printed))
        ref = _fit(data, fam) if printed else fit
        obj, stat, diag = _recheck(data, fam, ref, fit.theta)
    residuals = {"shared_start": 0.0, "shared_velocity": 0.0, "stationarity": stat}
    message = {
        "diverging": "(8)-(9)",
        "parallel": "(12)-(13)",
        "independent": "single-line LSQ",
    }.get(kind, "normal equations (3)")
    common: dict[str, Any] = {
        "status": Status.OPTIMAL,
        "method": "closed_form",
        "solve_time": tm.elapsed,
        "message": message + (" as printed" if printed else ""),
    }

    def note(v: Verdict) -> str:
        if v.status is Status.ERROR:
            return f"verification failed: stationarity = {stat:.2e} > {REJECT_TOL:g}"
        return f"stationarity = {stat:.2e} > {VERIFY_TOL:g}"

    return _finish(
        data,
        fam,
        fit,
        fit.theta,
        residuals,
        obj,
        diag,
        common,
        strict=False,
        note=note,
        keep=ref if printed else None,
    )
