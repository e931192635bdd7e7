r"""Running identification of the plane, as in the paper's example.

:func:`identify_sequence` updates the closed form (1.5)-(1.7) in O(1) per measurement
(running weighted sums), applies the re-check and the χ² and line tests of
:mod:`optmodels.plane.statistics` at every step, and optionally re-solves the generic
problem (warm-started) every few steps; the result is a :class:`PlaneSequence`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    REJECT_TOL,
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_number,
    as_probability,
    timed,
)
from optmodels.plane.closedform import _closed_form_from_sums, _scaled_sums
from optmodels.plane.data import PlaneData
from optmodels.plane.generic import Formulation, solve
from optmodels.plane.statistics import _planarity_arrays


@dataclass
class PlaneSequence:
    """Running plane identification, one row per step (a new measurement).

    Attributes
    ----------
    times : (K,) time of each step; n_points : (K,) measurements used so far.
    normal : (K, 3), offset : (K,) -- closed form (1.5)-(1.7); NaN where not ``resolved``.
    statistic : (K,) Λ_min (1.16), the minimum of (1.2) (defined at every step).
    dof, threshold, p_value, planar : (K,) the χ² test at ``level``; ``p_value`` is NaN
        and ``planar`` False where not ``resolved``.
    paper_statistic, paper_threshold, paper_planar : (K,) the paper's rule (1.17);
        ``paper_planar`` False where not ``resolved``.
    resolved : (K,) bool
        The data so far determine the plane: the line hypothesis is rejected at ``level``
        (``line_statistic > line_threshold``, see :class:`PlanarityTest`) **and** the
        normal passes its numerical re-check (estimated error ``numerical_error`` ≤ 1e-3
        rad, :func:`closed_form`). Scale invariant (whitened eigenvalues) and
        conditioning-aware. Where False no plane is reported.
    line_statistic, line_threshold : (K,) Λ₁ + Λ₂ (χ²(2N − 4) on a line) and its
        threshold at ``level``.
    line_direction : (K, 3) unit direction of the best-fitting line where not
        ``resolved`` (what the data do determine), NaN where resolved.
    numerical_error : (K,) estimated error (rad) of the closed-form normal, the Newton
        step of the re-check (inf: not determined to working precision).
    solve_time : float, seconds for the whole closed-form track.
    generic : dict or None
        With ``resolve_every``: ``index`` (J,) into the steps, ``normal`` (J, 3),
        ``offset`` (J,), ``objective`` (J,), ``status`` (J,) and ``solve_time`` of the
        warm-started generic re-solves (on resolved steps only; an unresolved step has
        status ``"unresolved"`` and NaN values).
    """

    times: FloatArray
    n_points: FloatArray
    normal: FloatArray
    offset: FloatArray
    statistic: FloatArray
    dof: FloatArray
    threshold: FloatArray
    p_value: FloatArray
    planar: np.ndarray
    paper_statistic: FloatArray
    paper_threshold: FloatArray
    paper_planar: np.ndarray
    level: float
    solve_time: float
    resolved: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    line_statistic: FloatArray = field(default_factory=lambda: np.zeros(0))
    line_threshold: FloatArray = field(default_factory=lambda: np.zeros(0))
    line_direction: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    numerical_error: FloatArray = field(default_factory=lambda: np.zeros(0))
    generic: dict[str, Any] | None = None


def identify_sequence(
    times: ArrayLike,
    points: ArrayLike,
    cov: ArrayLike,
    alpha2: ArrayLike | None = None,
    start: float | None = None,
    *,
    level: float = 0.997,
    resolve_every: int | None = None,
    formulation: Formulation = "reduced",
) -> PlaneSequence:
    """Re-estimate the plane after every measurement from time ``start`` on.

    The closed form is updated in O(1) per measurement: running sums of
    :math:`\alpha_i^{-2}`, :math:`\alpha_i^{-2} x_i` and :math:`\alpha_i^{-2} x_i x_i^T`
    (about the first point, divided by the spread) give ``Q`` (1.5) at every step,
    followed by one 3x3 eigenproblem per step (done for all steps at once) and the
    re-check of :func:`closed_form`.

    A step is ``resolved`` when the points so far are not on a line at ``level`` -- the
    two smallest generalized eigenvalues of (Q, D), Λ₁ + Λ₂ (the minimum of (1.2) over
    lines, χ²(2N − 4) under the line hypothesis), exceed ``chi2.ppf(level, 2N − 4)`` --
    and the normal's estimated numerical error is ≤ 1e-3 rad. Unresolved steps report
    no plane (NaN normal and offset, ``planar`` False) and the line direction instead.

    Parameters
    ----------
    times : (N,) strictly increasing measurement times (s).
    points, cov, alpha2 : as :class:`PlaneData` (m, m²); the covariances must satisfy
        (1.4).
    start : float, optional
        First time (s) at which to identify (the paper: 2 s after the first measurement).
        Default: as soon as 4 points are in (the test needs N >= 4).
    level : float
        Level of the χ² test and of the line test, in (0, 1).
    resolve_every : int, optional
        Also re-solve the generic problem every ``resolve_every`` (≥ 1) steps,
        warm-started from the previous generic solution (one start).
    formulation : {"reduced", "full"}
        Formulation of those generic re-solves.
    """
    data = PlaneData(points, cov, alpha2)  # type: ignore[arg-type]  # (checked there)
    t = as_finite_array("plane.identify_sequence times", times, shape=(data.n_points,))
    if np.any(np.diff(t) <= 0):
        raise ProblemError("plane.identify_sequence times: must be strictly increasing")
    if data.base_cov is None or data.alpha2 is None:
        raise ProblemError(
            "cov: the sequential closed form needs proportional covariances (1.4); for "
            "general D_i call plane.solve on each window"
        )
    lv = as_probability("plane.identify_sequence level", level, low_open=True, high_open=True)
    formulation = as_choice(
        "plane.identify_sequence formulation",  # type: ignore[assignment]
        formulation,
        ("full", "reduced"),
    )
    every = (
        None
        if resolve_every is None
        else as_count("plane.identify_sequence resolve_every", resolve_every, minimum=1)
    )
    if start is None:
        first = 3
    else:
        t0 = as_number("plane.identify_sequence start", start)
        first = max(int(np.searchsorted(t, t0, side="left")), 3)  # at least 4 points
    if first >= data.n_points:
        raise ProblemError(
            f"plane.identify_sequence start: no step with at least 4 measurements at or "
            f"after t = {start}"
        )

    with timed() as tm:
        s0, s1, s2, s2abs, ref, spread = _scaled_sums(data.points, data.alpha2, cumulative=True)
        count = np.arange(first + 1, data.n_points + 1, dtype=float)
        eig = _closed_form_from_sums(
            s0[first:], s1[first:], s2[first:], s2abs[first:], count, data.base_cov / spread**2
        )
        normal = eig.normal
        offset = spread * np.sum(normal * eig.mean, axis=-1) + normal @ ref  # (1.7)
        lead = np.take_along_axis(normal, np.argmax(normal != 0, axis=-1)[:, None], -1)[:, 0]
        flip = (offset < 0) | ((offset == 0) & (lead < 0))  # the sign of _canonical_sign
        normal = np.where(flip[:, None], -normal, normal)
        offset = np.abs(offset)
        stat = eig.check.rho
        line_stat = eig.lam[:, 0] + eig.lam[:, 1]
        err = eig.check.step
        arr = _planarity_arrays(stat, count, lv, line_stat, err <= REJECT_TOL)
        resolved = arr["resolved"]
        normal = np.where(resolved[:, None], normal, np.nan)
        offset = np.where(resolved, offset, np.nan)
        line_dir = np.where(resolved[:, None], np.nan, eig.line)

    generic = None
    if every is not None:
        generic = _sequence_generic(data, first, every, formulation, resolved)
    return PlaneSequence(
        times=t[first:],
        n_points=count,
        normal=normal,
        offset=offset,
        statistic=stat,
        dof=arr["dof"],
        threshold=arr["threshold"],
        p_value=arr["p_value"],
        planar=arr["planar"],
        paper_statistic=arr["paper_statistic"],
        paper_threshold=arr["paper_threshold"],
        paper_planar=arr["paper_planar"],
        level=lv,
        solve_time=tm.elapsed,
        resolved=resolved,
        line_statistic=line_stat,
        line_threshold=arr["line_threshold"],
        line_direction=line_dir,
        numerical_error=err,
        generic=generic,
    )


def _sequence_generic(
    data: PlaneData, first: int, every: int, formulation: Formulation, resolved: np.ndarray
) -> dict[str, Any]:
    assert data.base_cov is not None and data.alpha2 is not None
    steps = np.arange(first, data.n_points, every)
    normals = np.full((len(steps), 3), np.nan)
    offsets = np.full(len(steps), np.nan)
    objs = np.full(len(steps), np.nan)
    status: list[str] = []
    total = 0.0
    prev: FloatArray | None = None
    for j, i in enumerate(steps):
        if not resolved[i - first]:
            status.append("unresolved")
            continue
        sub = PlaneData(data.points[: i + 1], data.base_cov, data.alpha2[: i + 1])
        sol = solve(sub, formulation, starts=3 if prev is None else 1, initial_normal=prev)
        total += sol.build_time + sol.solve_time
        status.append(sol.status.value)
        if sol.ok:
            normals[j], offsets[j], objs[j] = sol.normal, sol.offset, sol.objective
            prev = sol.normal
    return {
        "index": steps - first,
        "normal": normals,
        "offset": offsets,
        "objective": objs,
        "status": status,
        "solve_time": total,
    }
