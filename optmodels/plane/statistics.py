r"""Statistics of the plane estimate.

:func:`planarity_test`: the χ²(N − 3) test of planar motion on Λ_min (1.16), with the
paper's rule (1.17) beside it (see the errata) and the line test behind ``resolved``;
:func:`cramer_rao_bound` for (tilts, a); :func:`angle_error` and :func:`plane_errors`
against a true plane.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_float_array,
    as_instance,
    as_number,
    as_probability,
)
from optmodels.plane.closedform import closed_form
from optmodels.plane.data import (
    PlaneData,
    _check_plane,
    _quad_forms,
    reduced_objective,
)
from optmodels.plane.general import line_test
from optmodels.plane.generic import solve
from optmodels.plane.solution import PlaneSolution


@dataclass(frozen=True)
class PlanarityTest:
    """χ² test of the hypothesis "the target moves in a plane".

    Attributes
    ----------
    statistic : float
        :math:`\\Lambda_{\\min}` = minimum of (1.2), (1.16).
    dof : int
        ``N - 3``: N residuals, three fitted plane parameters (two for the direction of
        ``n``, one for ``a``).
    level : float
        Probability of accepting a planar motion (1 - false-alarm rate).
    threshold : float
        ``chi2.ppf(level, dof)``: reject when ``statistic > threshold``.
    p_value : float
        ``chi2.sf(statistic, dof)``.
    planar : bool
        ``statistic <= threshold``.
    paper_statistic, paper_threshold : float
        The printed rule (1.17): :math:`\\sqrt{2\\Lambda}` against :math:`\\sqrt{2N} + 2`.
    paper_planar : bool
        :math:`\\sqrt{2\\Lambda} \\le \\sqrt{2N} + 2`.
    paper_false_alarm : float
        The rule's actual false-alarm probability under χ²(N − 3) (the paper claims
        0.003).
    resolved : bool
        Whether the data determine the plane: the hypothesis "the points are on a line"
        is rejected at ``level`` (``line_statistic > line_threshold``). Only then does
        :math:`\\Lambda_{\\min}` follow χ²(N − 3) (a nearly straight track gives a
        statistic far below it, and every plane through the line fits about equally).
        When not resolved, ``planar`` and ``paper_planar`` are False.
    line_statistic : float
        The minimum of (1.2) over lines, χ²(2N − 4) for points on a line
        (:func:`optmodels.plane.general.line_test`). Under (1.4): Λ₁ + Λ₂, the two
        smallest eigenvalues of (Q, D). For general :math:`D_i`: the exact minimum
        (Newton over line directions) wherever it could be below ``line_threshold``, as
        :func:`fit_general` computes it (issue 26: the lower bound used before called a
        real climbing turn "unresolved"); a lower bound only where that bound already
        exceeds the threshold (the verdict is then certain).
    line_dof, line_threshold : int, float
        ``2N − 4`` and ``chi2.ppf(level, 2N − 4)``.
    """

    statistic: float
    dof: int
    level: float
    threshold: float
    p_value: float
    planar: bool
    paper_statistic: float
    paper_threshold: float
    paper_planar: bool
    paper_false_alarm: float
    resolved: bool = True
    line_statistic: float = float("nan")
    line_dof: int = 0
    line_threshold: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {k: (bool(v) if isinstance(v, np.bool_) else v) for k, v in self.__dict__.items()}


def _planarity_arrays(
    stat: FloatArray,
    n: FloatArray,
    level: float,
    line_stat: FloatArray,
    determined: np.ndarray | bool = True,
) -> dict[str, FloatArray]:
    """The χ²(N − 3) test, the rule (1.17) and the line test, vectorised.

    ``determined``: the normal passed its numerical re-check; ``resolved`` needs it and
    the rejection of the line hypothesis at ``level``.
    """
    dof = n - 3
    thr = stats.chi2.ppf(level, dof)
    paper_thr = np.sqrt(2.0 * n) + 2.0
    line_dof = 2 * n - 4
    line_thr = stats.chi2.ppf(level, line_dof)
    resolved = np.asarray(determined) & (line_stat > line_thr)
    paper_stat = np.sqrt(2.0 * np.maximum(stat, 0.0))
    return {
        "dof": dof,
        "threshold": thr,
        "p_value": np.where(resolved, stats.chi2.sf(stat, dof), np.nan),
        "planar": resolved & (stat <= thr),
        "paper_statistic": paper_stat,
        "paper_threshold": paper_thr,
        "paper_planar": resolved & (paper_stat <= paper_thr),
        "paper_false_alarm": stats.chi2.sf(paper_thr**2 / 2.0, dof),
        "resolved": resolved,
        "line_dof": line_dof,
        "line_threshold": line_thr,
    }


def planarity_test(
    data: PlaneData, solution: PlaneSolution | None = None, level: float = 0.997
) -> PlanarityTest:
    """χ² test of planar motion, with the paper's rule (1.17) beside it.

    Parameters
    ----------
    data : PlaneData
        Needs N >= 4 (with N = 3 the plane fits exactly and the test has no degrees of
        freedom).
    solution : PlaneSolution, optional
        A plane estimate; default :func:`closed_form` under (1.4), else :func:`solve`.
        The statistic is (1.12) at its ``normal`` and ``offset``.
    level : float
        Acceptance probability for a planar motion, in (0, 1), default 0.997 as in the
        paper; also the level of the line test behind ``resolved``.

    Returns
    -------
    PlanarityTest
        ``planar`` is True only if the plane is ``resolved`` (the points are not on a
        line, at ``level``) and :math:`\\Lambda_{\\min}` is below the χ²(N − 3) threshold.
    """
    lv = as_probability("plane.planarity_test level", level, low_open=True, high_open=True)
    as_instance("plane.planarity_test data", data, PlaneData)
    if data.n_points < 4:
        raise ProblemError("points: the planarity test needs N >= 4 (dof = N - 3)")
    if solution is None:
        solution = (
            closed_form(data, level=None)
            if data.proportional
            else solve(data, level=None).require_ok()
        )
    if not isinstance(solution, PlaneSolution):
        raise ProblemError(
            "plane.planarity_test solution: expected a PlaneSolution, got "
            f"{type(solution).__name__}"
        )
    if solution.resolved is False and "rejected" in solution.info:
        # an unresolved fit: Λ_min at the plane it fitted (the statistic is defined, the
        # plane is not determined; the test then reports resolved=False)
        normal, offset = solution.info["rejected"]["normal"], solution.info["rejected"]["offset"]
    else:
        solution.require_ok()
        normal, offset = solution.normal, solution.offset
    stat = reduced_objective(data, normal, offset)
    lt = line_test(data, lv)
    line = lt.statistic
    arr = _planarity_arrays(
        np.asarray(stat),
        np.asarray(float(data.n_points)),
        lv,
        np.asarray(line),
        determined=bool(lt.resolved or not line > lt.threshold),
    )
    return PlanarityTest(
        statistic=stat,
        dof=int(arr["dof"]),
        level=lv,
        threshold=float(arr["threshold"]),
        p_value=float(arr["p_value"]),
        planar=bool(arr["planar"]),
        paper_statistic=float(arr["paper_statistic"]),
        paper_threshold=float(arr["paper_threshold"]),
        paper_planar=bool(arr["paper_planar"]),
        paper_false_alarm=float(arr["paper_false_alarm"]),
        resolved=bool(arr["resolved"]),
        line_statistic=line,
        line_dof=int(arr["line_dof"]),
        line_threshold=float(arr["line_threshold"]),
    )


@dataclass(frozen=True)
class CramerRao:
    """Cramér–Rao bound for (tilt_1, tilt_2, a) at a true plane.

    Attributes
    ----------
    cov : ndarray (3, 3)
        Bound on the covariance of (tilt about ``tangent[0]``... in radians: the small
        rotations of ``n`` towards ``tangent[0]`` and ``tangent[1]``, and ``a`` in metres).
    tangent : ndarray (2, 3)
        Orthonormal basis of the plane used for the tilts.
    angle_rms : float
        :math:`\\sqrt{\\mathrm{tr}\\, cov_{tilt}}`: bound on the RMS angle between the
        estimated and true normals (rad).
    offset_std : float
        :math:`\\sqrt{cov_{aa}}` (m).
    """

    cov: FloatArray
    tangent: FloatArray
    angle_rms: float
    offset_std: float


def cramer_rao_bound(data: PlaneData, normal: ArrayLike, offset: float) -> CramerRao:
    """Cramér–Rao bound of the plane parameters, ``data.points`` being the *true* points.

    Derivation: with :math:`x_i = a n + T u_i` (``T`` a basis of the plane, :math:`u_i`
    nuisance), eliminating :math:`u_i` from the Fisher information of
    :math:`x_i^* \\sim N(x_i, D_i)` leaves
    :math:`D_i^{-1} - D_i^{-1}T(T^TD_i^{-1}T)^{-1}T^TD_i^{-1} = n n^T / (n^T D_i n)`, so
    only the normal component of each point informs the plane, and
    :math:`J = \\sum_i h_i h_i^T / (n^T D_i n)` with
    :math:`h_i = (\\langle t_1, x_i\\rangle, \\langle t_2, x_i\\rangle, -1)`, the gradient
    of :math:`\\langle n(\\delta), x_i\\rangle - a` in (tilts δ, a). The bound is
    :math:`J^{-1}`.
    """
    n, offset = _check_plane("plane.cramer_rao_bound", data, normal, offset)
    n = n / np.linalg.norm(n)
    # tangent basis: complete n to an orthonormal frame
    _, _, vt = np.linalg.svd(n[None, :])
    tangent = vt[1:]
    x = data.points
    h = np.column_stack([x @ tangent[0], x @ tangent[1], -np.ones(len(x))])
    w = 1.0 / _quad_forms(data.covs, n)
    fisher = (h * w[:, None]).T @ h
    ev = np.linalg.eigvalsh(fisher)
    if not ev[0] > 1e-13 * ev[-1]:
        raise ProblemError(
            "plane.cramer_rao_bound data: the Fisher information is singular (eigenvalues "
            f"{ev[0]:.3g} ... {ev[-1]:.3g}): the true points do not determine the plane "
            "(collinear?), the bound is infinite"
        )
    cov = np.linalg.inv(fisher)
    return CramerRao(
        cov=cov,
        tangent=tangent,
        angle_rms=float(np.sqrt(cov[0, 0] + cov[1, 1])),
        offset_std=float(np.sqrt(cov[2, 2])),
    )


def _direction_stack(name: str, value: ArrayLike) -> FloatArray:
    a = as_float_array(name, value)  # ragged, text, None entries, complex: refused
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ProblemError(f"{name}: expected shape (..., 3), got {a.shape}")
    if np.any(np.isinf(a)) or np.any(np.abs(a[np.isfinite(a)]) > MAX_MAGNITUDE):
        raise ProblemError(f"{name}: infinite or huge entries")
    nrm = np.linalg.norm(a, axis=-1)
    if np.any(nrm == 0):
        raise ProblemError(f"{name}: zero vectors have no direction")
    return a


def angle_error(normal: ArrayLike, true_normal: ArrayLike) -> FloatArray:
    """Angle (rad) between estimated and true normals, ignoring the common sign of (n, a).

    Works on stacks (..., 3). Uses ``atan2(‖n × m‖, |n·m|)``, accurate for tiny angles.
    NaN rows (e.g. the unresolved steps of :class:`PlaneSequence`) give NaN; infinite,
    complex or zero vectors are refused.
    """
    a = _direction_stack("plane.angle_error normal", normal)
    b = _direction_stack("plane.angle_error true_normal", true_normal)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.arctan2(cross, np.abs(np.sum(a * b, axis=-1)))


def plane_errors(
    normal: ArrayLike, offset: ArrayLike, true_normal: ArrayLike, true_offset: float
) -> tuple[FloatArray, FloatArray]:
    """(angle error in rad, offset error in m) with (n, a) sign-aligned to the truth.
    Stacks (..., 3) and (...,) work; NaN rows give NaN (see :func:`angle_error`)."""
    n = _direction_stack("plane.plane_errors normal", normal)
    a = as_float_array("plane.plane_errors offset", offset)
    if a.shape != n.shape[:-1] or np.any(np.isinf(a)):
        raise ProblemError(
            f"plane.plane_errors offset: expected finite values (NaN allowed) "
            f"of shape {n.shape[:-1]}, got shape {a.shape}"
        )
    if np.any(np.isnan(a) & ~np.any(np.isnan(n), axis=-1)):
        raise ProblemError(
            "plane.plane_errors offset: NaN where the normal is a number (NaN only on "
            "the NaN rows of an unresolved step)"
        )
    true_offset = as_number("plane.plane_errors true_offset", true_offset)
    m = _direction_stack("plane.plane_errors true_normal", true_normal)
    sign = np.sign(np.sum(n * m, axis=-1))
    sign = np.where(sign == 0, 1.0, sign)
    return angle_error(n, m), sign * a - true_offset
