"""The re-check of any answer against the original problem of paper 002 (see the package
notes): the exact Newton step to the least-squares optimum ("stationarity"), the
violation of the family's equalities by a generic solve's lines, the tolerances
:data:`VERIFY_TOL` / :data:`REJECT_TOL`, and the downgrade rules for coarse times
(:data:`~optmodels.trajectories.moments.TIME_RESOLUTION_WARN`) and a far epoch
(:data:`EXTRAPOLATION_WARN`, :data:`EXTRAPOLATION_MAX`); and the end of every solve and
closed form: :func:`_finish` (the one gate :func:`optmodels.core.finish` on these NumPy
residuals, then the coarse-time / far-epoch downgrade) and :func:`_finish_solve` (a
generic solve's point: re-check, line residuals, strict gate).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optmodels.core import REJECT_TOL as REJECT_TOL
from optmodels.core import VERIFY_TOL as VERIFY_TOL
from optmodels.core import FloatArray, ProblemError, Status, Verdict, finish
from optmodels.trajectories.data import Family, TrajectoryData
from optmodels.trajectories.fits import _Fit
from optmodels.trajectories.moments import EPS, TIME_RESOLUTION_WARN, _per, _Stats, _stats
from optmodels.trajectories.solution import TrajectorySolution, _failure, _package

#: Relative violation (equalities, stationarity) above which a solver's claimed optimum
#: is downgraded by :func:`solve`: OPTIMAL → OPTIMAL_INACCURATE, and OPTIMAL_INACCURATE →
#: ERROR (never returned as a solution). Above REJECT_TOL a claimed OPTIMAL becomes ERROR
#: too. These are the core's thresholds; the rule is the one gate
#: (:func:`optmodels.core.gate`, strict for a solver's claim, plain for the closed forms);
#: ``VERIFY_TOL`` and ``REJECT_TOL`` here are :data:`optmodels.core.VERIFY_TOL` and
#: :data:`optmodels.core.REJECT_TOL`, imported above.

#: Rounding of the reported start at ``epoch`` in units of the standard deviation of the
#: object's position at its data, ``eps·|V_j (T_j − epoch)|·√Σw``, counted when the epoch
#: is more than 10 spans from the data: above EXTRAPOLATION_WARN the status is at best
#: OPTIMAL_INACCURATE, above EXTRAPOLATION_MAX ``epoch`` is refused (the reported start
#: and velocity no longer reproduce the fitted line at the data).
EXTRAPOLATION_WARN = 1e-2
EXTRAPOLATION_MAX = 1.0


# --------------------------------------------------------------------------- re-check
def _lines(st: _Stats, fam: Family, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each object's line (position at T_j, velocity) implied by θ, (Q, d) each."""
    v = theta[fam.velocity_index]
    return theta[fam.start_index] + v * st.u, v


def _newton(st: _Stats, fam: Family, fit: _Fit, gp: FloatArray, gv: FloatArray) -> FloatArray:
    """Ψ·∇(−W/2) at a point whose per-object gradients are ``gp = Σw r``,
    ``gv = Σw(t − T_j) r``: the exact step to the family's least-squares optimum (W is
    quadratic), computed without forming the ill-conditioned products of θ's basis."""
    si, vi = fam.start_index, fam.velocity_index
    s0, m2, u = st.s0, st.m2, st.u
    if fit.kind in ("independent", "parallel"):
        dp = gp / s0
        dv = gv / m2 if fit.kind == "independent" else (gv.sum(axis=0) / m2.sum(axis=0))[None]
        dvj = dv[vi - len(fam.start_groups)]
        return np.vstack([dp - u * dvj, dv])
    if fit.kind == "diverging":
        c, g, var0 = fit.ctx["c"], fit.ctx["g"], fit.ctx["var0"]
        ds = var0 * np.sum(gp * m2 / c - g * gv, axis=0)
        dv = (gv + u * gp) / c - g * ds
        return np.vstack([ds, dv])
    out = np.empty((fam.n_params, st.s0.shape[1]))
    for k in range(out.shape[1]):
        lever = fit.ctx["lever"][k]
        gc = np.zeros(fam.n_params)
        np.add.at(gc, si, gp[:, k])
        np.add.at(gc, vi, gv[:, k] + lever * gp[:, k])
        out[:, k] = fit.ctx["jac"][k] @ (fit.ctx["psic"][k] @ gc)
    return out


def _recheck(
    data: TrajectoryData, fam: Family, fit: _Fit, theta: FloatArray
) -> tuple[float, float, dict[str, Any]]:
    """Objective, stationarity and diagnostics of θ against the original problem, in
    centred times. Stationarity: max over θ of |Δθ_k| / max(max |θ| of its kind, std_k),
    Δθ the exact step to the optimum."""
    st = _stats(data)
    p, v = _lines(st, fam, theta)
    w = data.w
    with np.errstate(all="ignore"):
        r = st.ry + (st.p - p)[data.obj] - v[data.obj] * st.tau
        obj = float(np.sum(w * r * r))
        gp, gv = _per(data, w * r), _per(data, w * r * st.tau)
        step = _newton(st, fam, fit, gp, gv)
        std = np.sqrt(np.diagonal(fit.cov, axis1=1, axis2=2)).T  # (R, d)
        ns = len(fam.start_groups)
        size = np.empty_like(theta)
        size[:ns] = np.max(np.abs(theta[:ns]))
        size[ns:] = np.max(np.abs(theta[ns:]))
        stat = float(np.max(np.abs(step) / np.maximum(size, std)))
        far = np.abs(st.u) > 10.0 * st.span[:, None]
        xr = np.where(far, EPS * np.abs(v * st.u) * np.sqrt(st.s0), 0.0)
    if not (np.isfinite(stat) and np.isfinite(obj)):
        stat = float("inf")
    diag = {
        "time_resolution": float(np.max(st.kappa)),
        "extrapolation": float(np.max(xr)),
        "extrapolation_object": int(np.argmax(np.max(xr, axis=1))),
    }
    return obj, stat, diag


def _downgrade(data: TrajectoryData, status: Status, diag: dict[str, Any]) -> tuple[Status, str]:
    """OPTIMAL → OPTIMAL_INACCURATE for coarse times or a far epoch; refuse an epoch whose
    start cannot carry the line."""
    notes = []
    if diag["extrapolation"] > EXTRAPOLATION_MAX:
        j = diag["extrapolation_object"]
        raise ProblemError(
            f"trajectories epoch: {data.epoch:.6g} s is so far from the data that the start "
            f"there cannot carry the fitted line: rounding the reported start of object {j} "
            f"moves its line at the data by {diag['extrapolation']:.3g} standard deviations; "
            "use an epoch nearer the data"
        )
    if diag["extrapolation"] > EXTRAPOLATION_WARN:
        notes.append(
            f"epoch {data.epoch:.6g} s is far from the data: the reported starts are "
            f"extrapolations whose rounding moves the lines at the data by up to "
            f"{diag['extrapolation']:.2g} standard deviations"
        )
    if diag["time_resolution"] > TIME_RESOLUTION_WARN:
        notes.append(
            f"float64 resolves the times' spread only to "
            f"{diag['time_resolution']:.2g} relative (|t| large against the spread)"
        )
    if notes and status is Status.OPTIMAL:
        status = Status.OPTIMAL_INACCURATE
    return status, "; ".join(notes)


def _line_residuals(
    st: _Stats,
    fam: Family,
    p: FloatArray,
    v: FloatArray,
    u: FloatArray,
    dt: FloatArray,
    std: FloatArray,
) -> dict[str, float]:
    """Violation of the family's equalities by Q lines given at reference times
    (position ``p`` at T0_j, velocity ``v``; ``u = T0_j − epoch``, ``dt`` (Q,) T0_j − T0_0):
    velocities relative to max(|V|, σ_V); starts of objects that also share a velocity as
    positions at the data (p_j − p_k = (T0_j − T0_k)V), relative to max(|p|, σ_p); other
    shared starts at the epoch, relative to max(|y0|, σ_y0)."""
    ns = len(fam.start_groups)
    vi = fam.velocity_index
    sv = max(float(np.max(np.abs(v))), float(np.max(std[ns:])))
    sp_ = max(float(np.max(np.abs(p))), float(np.max(1.0 / np.sqrt(st.s0))))
    s = p - v * u
    ss = max(float(np.max(np.abs(s))), float(np.max(std[:ns])))
    wv = (
        max(
            (
                float(np.max(np.abs(v[list(g)] - v[g[0]])))
                for g in fam.velocity_groups
                if len(g) > 1
            ),
            default=0.0,
        )
        / sv
    )
    ws = 0.0
    for g in fam.start_groups:
        r = g[0]
        for j in g[1:]:
            if vi[j] == vi[r]:
                gap = np.abs(p[j] - p[r] - (dt[j] - dt[r]) * v[r]) / sp_
            else:
                gap = np.abs(s[j] - s[r]) / ss
            ws = max(ws, float(np.max(gap)))
    return {"shared_start": ws, "shared_velocity": wv}


# --------------------------------------------------------------------------- the gate
def _finish(
    data: TrajectoryData,
    fam: Family,
    fit: _Fit,
    theta: FloatArray,
    residuals: dict[str, float],
    objective: float,
    diag: dict[str, Any],
    common: dict[str, Any],
    *,
    strict: bool,
    note: Any,
    keep: _Fit | None = None,
) -> TrajectorySolution:
    """Pack θ and pass it through the one gate (:func:`optmodels.core.finish`, ``strict``
    for a solver's claim, see :func:`optmodels.core.gate`). Refused: the failure form
    (:func:`_failure`, θ kept in ``info["rejected_theta"]``), or with ``keep`` (the
    misprinted (13)) the numbers under status ERROR, packed with the fit ``keep``.
    Accepted: :func:`_downgrade` (coarse times, far epoch). ``diag`` goes to
    ``info`` except for a refused solver point."""
    sol = _package(data, fam, fit, theta, residuals, objective, common)

    def reject(s: TrajectorySolution) -> TrajectorySolution:
        failed = dict(common, status=s.status, message=s.message)
        if keep is not None:
            out = _package(data, fam, keep, theta, residuals, objective, failed)
        else:
            out = _failure(data, fam, fit, residuals, failed, theta)
        if not strict:
            out.info.update(diag)
        return out

    sol = finish(sol, strict=strict, note=note, reject=reject)
    if sol.ok:
        sol.status, text = _downgrade(data, sol.status, diag)
        if text:
            sol.message += "; " + text
        sol.info.update(diag)
    return sol


def _solve_note(v: Verdict) -> str:
    return f"verification failed: {v.key} = {v.worst:.2e} > {VERIFY_TOL:g}"


def _finish_solve(
    data: TrajectoryData,
    fam: Family,
    fit: _Fit,
    theta: FloatArray,
    lines: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None,
    common: dict[str, Any],
) -> TrajectorySolution:
    """End of :func:`~.generic.solve` for a finite solver point θ (and the solver's own
    lines, constrained formulation): the re-check against the original problem
    (stationarity; the equalities of the family by the lines), the one gate in its strict
    form (a claimed optimum above VERIFY_TOL is OPTIMAL_INACCURATE if it was OPTIMAL and
    stays within REJECT_TOL, else refused), then the downgrades of :func:`_finish`."""
    obj, stat, diag = _recheck(data, fam, fit, theta)
    std = np.sqrt(np.diagonal(fit.cov, axis1=1, axis2=2)).T
    residuals = (
        {"shared_start": 0.0, "shared_velocity": 0.0}
        if lines is None
        else _line_residuals(_stats(data), fam, *lines, std)
    )
    residuals["stationarity"] = stat
    sol = _finish(
        data, fam, fit, theta, residuals, obj, diag, common, strict=True, note=_solve_note
    )
    if lines is not None and sol.ok:
        sol.info["lines"] = {
            "position": lines[0],
            "velocity": lines[1],
            "at_time": (lines[2][:, 0] + data.epoch),
        }
    return sol
