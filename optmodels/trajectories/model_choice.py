"""Model choice for paper 002: does a dependent family fit as well as independent lines?
The likelihood-ratio (σ² known, χ²) or F (σ² estimated) test of the family's equality
constraints, :func:`family_test`, with its result :class:`FamilyTest`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from scipy import stats

from optmodels.core import ProblemError, Status, as_choice, as_instance, as_probability
from optmodels.trajectories.closedform import closed_form
from optmodels.trajectories.data import Family, FamilyName, TrajectoryData, resolve_family
from optmodels.trajectories.fits import _fit, _kind
from optmodels.trajectories.moments import EPS, _stats
from optmodels.trajectories.verify import _lines


# --------------------------------------------------------------------------- model choice
@dataclass(frozen=True)
class FamilyTest:
    """Does the family fit as well as independent lines?

    ``statistic``: with σ² known, Λ = W_family − W_independent ~ χ²(dof); with σ² estimated
    from the independent fit, F = (Λ/dof)/(W_independent/dof2) ~ F(dof, dof2). ``reject``:
    the family is rejected at ``level``. ``message`` carries the fits' notes when one of
    them is OPTIMAL_INACCURATE.
    """

    family: str
    sigma2: str
    statistic: float
    dof: int
    dof2: int | None
    threshold: float
    p_value: float
    level: float
    reject: bool
    objective_family: float
    objective_independent: float
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def family_test(
    data: TrajectoryData,
    family: FamilyName | Family = "diverging",
    *,
    level: float = 0.95,
    sigma2: Literal["known", "estimated"] = "known",
) -> FamilyTest:
    """Likelihood-ratio test of the family's equality constraints against independent lines.

    The family imposes ``q = 2Q − R`` linear constraints per coordinate. Under the family
    and Gaussian errors, ``Λ = W_family − W_independent`` (both in units of σ², the
    objectives of :func:`closed_form`) is χ² with ``q·d`` degrees of freedom when the
    variances are known (``sigma2="known"``); when they are known only up to a common
    factor (``"estimated"``), ``F = (Λ/(q d)) / (W_independent/((Σ N_j − 2Q) d))`` is
    F(q d, (Σ N_j − 2Q) d). Λ is computed as the constraint penalty
    Σ_j Σw_j (ȳ_j − p_j)² + Σw(t − T_j)²(V̂_j − V_j)² (each object's own line against the
    family's), which equals the difference of the objectives without its cancellation.

    Raises
    ------
    ProblemError
        ``level`` not in (0, 1), ``sigma2`` not "known"/"estimated", an independent family
        (nothing to test), too few measurements to estimate σ², data on which the
        independent lines fit exactly (W_independent at the rounding level: σ² cannot be
        estimated and F is undefined), or a fit that fails its re-check.
    """
    level = as_probability("trajectories.family_test level", level, low_open=True, high_open=True)
    mode = as_choice("trajectories.family_test sigma2", sigma2, ("known", "estimated"))
    as_instance("trajectories.family_test data", data, TrajectoryData)
    fam = resolve_family(family, data.n_objects)
    if fam.n_constraints == 0:
        raise ProblemError("family: independent lines impose no constraint to test")
    fits = {}
    notes = []
    for key, f in (("family", fam), ("independent", Family.independent(data.n_objects))):
        sol = closed_form(data, f)
        if not sol.ok:
            raise ProblemError(
                f"family: the {key} fit fails its re-check ({sol.message}); "
                "the test would be meaningless"
            )
        if sol.status is not Status.OPTIMAL:
            notes.append(f"{key} fit {sol.status.value}: {sol.message}")
        fits[key] = sol
    wf, wi = fits["family"].objective, fits["independent"].objective
    lam = float(max(_fit(data, fam).ctx.get("lam", wf - wi), 0.0))
    if _kind(fam) == "custom":
        lam = _custom_penalty(data, fam)
    dof = fam.n_constraints * data.dim
    if mode == "known":
        stat, dist, dof2 = lam, stats.chi2(dof), None
    else:
        dof2 = (data.n_measurements - 2 * data.n_objects) * data.dim
        if dof2 <= 0:
            raise ProblemError(
                "sigma2: estimating σ² needs more than 2 measurements on some object (Σ N_j > 2Q)"
            )
        st = _stats(data)
        resid_scale = float(
            np.sum(data.w * (np.abs(st.ry) + np.abs(st.vhat[data.obj] * st.tau)) ** 2)
        )
        if not wi > (1e3 * EPS) ** 2 * resid_scale:
            raise ProblemError(
                f"trajectories.family_test sigma2: the independent lines fit the data "
                f"exactly (W_independent = {wi:.3g}, at the float64 rounding level of the "
                "data), so σ² cannot be estimated and the F test is undefined; use "
                "sigma2='known' with the measurement variances"
            )
        stat, dist = (lam / dof) / (wi / dof2), stats.f(dof, dof2)
    thr = float(dist.ppf(level))
    return FamilyTest(
        family=fam.name,
        sigma2=mode,
        statistic=float(stat),
        dof=dof,
        dof2=dof2,
        threshold=thr,
        p_value=float(dist.sf(stat)),
        level=level,
        reject=bool(stat > thr),
        objective_family=wf,
        objective_independent=wi,
        message="; ".join(notes),
    )


def _custom_penalty(data: TrajectoryData, fam: Family) -> float:
    """Λ of a custom family: Σ_j N_j (ȳ_j − p_j)² + M2_j (V̂_j − V_j)² at its fit."""
    st = _stats(data)
    p, v = _lines(st, fam, _fit(data, fam).theta)
    return float(np.sum(st.s0 * (st.p - p) ** 2 + st.m2 * (st.vhat - v) ** 2))
