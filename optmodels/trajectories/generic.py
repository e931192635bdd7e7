"""The generic solve of paper 002's least squares (1): a CVXPY model, either the ``Q``
lines with the family's equality constraints (``"constrained"``) or the unconstrained
problem in θ with the design matrix (``"reduced"``), in centred, scaled units, with
the back-end's options for the class ``"lsq"`` (:data:`SOLVER_DEFAULTS`, the table
:data:`optmodels.backends.profiles.DEFAULTS` ``["lsq"]``); the answer is re-checked in NumPy
(:mod:`.verify`).

Compile once, solve many (issue 27): :func:`solve` builds a *parametric* (DPP) model
(:func:`_parametric_model`) whose data -- the scaled values and the start constraints'
offsets -- are ``cp.Parameter``; the model is kept (:data:`_MODELS`, the last
:data:`MODEL_CACHE_SIZE` structures: formulation, family, object sizes, times and
weights) so that a repeated solve on the same design (a Monte Carlo trial, a harness
repetition) only sets the parameters and skips CVXPY's canonicalisation. The
non-parametric model (:func:`_cvxpy_problem`) is kept as the reference the tests compare
with.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from typing import Any, Literal

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.backends.profiles import DEFAULTS
from optmodels.backends.profiles import solver_options as backend_options
from optmodels.core import FloatArray, ProblemError, as_choice, as_instance, timed
from optmodels.trajectories.data import Family, FamilyName, TrajectoryData, resolve_family
from optmodels.trajectories.fits import _anchors, _fit
from optmodels.trajectories.moments import _stats
from optmodels.trajectories.solution import TrajectorySolution, _failure
from optmodels.trajectories.verify import _finish_solve

#: Default solver options: the back-end's table for equality-constrained least squares
#: (the same object; the reasons for each value are given there).
SOLVER_DEFAULTS: dict[str, dict[str, Any]] = DEFAULTS["lsq"]


# --------------------------------------------------------------------------- generic solve
def _cvxpy_problem(data: TrajectoryData, fam: Family, formulation: str) -> tuple[cp.Problem, Any]:
    """The CVXPY model in centred, scaled units, and a function mapping the solved
    variables to (θ (R, d), lines (p, v, u, dt) or None).

    Each object's line is parametrised by its position at its own mean time T0_j
    (coordinate 0's weights) and its velocity -- the same lines, so the same problem; the
    shared-start equalities are written at the epoch (p_j − u_jV_j = p_k − u_kV_k), or as
    p_j − p_k = (T0_j − T0_k)V when the two objects also share the velocity. Times are
    divided by ts = max |t − T0_j|, values shifted by each object's mean and divided by
    their spread, weights by their mean, objective by N d: O(1) numbers for the solvers'
    tolerances (first-order solvers such as OSQP/SCS need it)."""
    st = _stats(data)
    n, q, d = data.n_measurements, data.n_objects, data.dim
    si, vi = fam.start_index, fam.velocity_index
    tau0 = st.tau[:, 0]
    u0 = st.u[:, 0]
    dt0 = (st.tbar[:, 0] - st.tbar[0, 0]) + (st.tcorr[:, 0] - st.tcorr[0, 0])
    sw = np.sqrt(data.w / np.mean(data.w) / (n * d))
    ts = float(np.max(np.abs(tau0))) or 1.0
    if formulation == "constrained":
        off = st.p  # (Q, d)
        yo = data.y - off[data.obj]
        ys = (
            max(
                float(np.max(np.abs(yo))),
                float(np.max(np.abs(off - off[0]))),
                float(np.max(np.abs(st.vhat))) * ts,
            )
            or 1.0
        )
        sel0 = sp.csr_matrix((np.ones(n), (np.arange(n), data.obj)), shape=(n, q))
        sel1 = sp.csr_matrix((tau0 / ts, (np.arange(n), data.obj)), shape=(n, q))
        pv = cp.Variable((q, d), name="position")
        v = cp.Variable((q, d), name="velocity")
        cons = []
        for g in fam.velocity_groups:
            if len(g) > 1:
                cons.append(v[list(g[1:])] == np.ones((len(g) - 1, 1)) @ v[[g[0]]])
        for g in fam.start_groups:
            r = g[0]
            for j in g[1:]:
                const = (off[j] - off[r]) / ys
                if vi[j] == vi[r]:
                    cons.append(pv[j] - pv[r] + const == ((dt0[j] - dt0[r]) / ts) * v[r])
                else:
                    cons.append(pv[j] - pv[r] + const == (u0[j] / ts) * v[j] - (u0[r] / ts) * v[r])
        obj = cp.sum_squares(cp.multiply(sw, yo / ys - sel0 @ pv - sel1 @ v))

        def back_c() -> tuple[FloatArray, Any]:
            pl = np.asarray(pv.value) * ys + off
            vl = np.asarray(v.value) * ys / ts
            vel = np.vstack([vl[list(g)].mean(axis=0) for g in fam.velocity_groups])
            vj = vel[vi - len(fam.start_groups)]
            s = pl - vj * u0[:, None]
            theta = np.vstack([[s[list(g)].mean(axis=0) for g in fam.start_groups], vel])
            return theta, (pl, vl, u0[:, None], dt0)

        return cp.Problem(cp.Minimize(obj), cons), back_c
    if formulation == "reduced":
        # (1): the unconstrained least squares in θ, anchored parameters (see _anchors)
        lever, a = _anchors(st, fam, 0)
        col = lever[data.obj] + tau0
        tsr = float(np.max(np.abs(col))) or 1.0
        ns = len(fam.start_groups)
        grp_off = np.vstack([[np.mean(st.p[list(g)], axis=0)] for g in fam.start_groups])
        yo = data.y - grp_off[si[data.obj]]
        ys = float(np.max(np.abs(yo))) or 1.0
        rows = np.concatenate([np.arange(n), np.arange(n)])
        cols = np.concatenate([si[data.obj], vi[data.obj]])
        am = sp.csr_matrix(
            (np.concatenate([np.ones(n), col / tsr]), (rows, cols)), shape=(n, fam.n_params)
        )
        th = cp.Variable((fam.n_params, d), name="theta")
        obj = cp.sum_squares(cp.multiply(sw, yo / ys - am @ th))

        def back_r() -> tuple[FloatArray, Any]:
            thc = np.asarray(th.value) * ys
            thc[ns:] /= tsr
            thc[:ns] += grp_off
            for gi, g in enumerate(fam.start_groups):
                if a[gi] != 0.0:
                    thc[gi] -= a[gi] * thc[vi[g[0]]]
            return thc, None

        return cp.Problem(cp.Minimize(obj)), back_r
    raise ProblemError(f"formulation: expected 'constrained' or 'reduced', got {formulation!r}")


#: How many parametric models :func:`solve` keeps (one per design: formulation, family,
#: object sizes, times, weights).
MODEL_CACHE_SIZE = 8
_MODELS: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
_MODELS_LOCK = threading.Lock()  # a CVXPY model is set, solved and read by one caller


def _digest(*arrays: Any) -> str:
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _parametric_model(
    data: TrajectoryData, fam: Family, formulation: str
) -> tuple[cp.Problem, Any, Any, bool]:
    """The model of :func:`_cvxpy_problem` with the data as CVXPY parameters (DPP), and a
    function ``set_values()`` that writes this data's values into the parameters and
    returns the back-transform (θ, lines). Models are cached by their structure (what the
    parameters do not carry: times, weights, object sizes, family); the last flag says
    whether this one came from the cache (no canonicalisation)."""
    st = _stats(data)
    n, q, d = data.n_measurements, data.n_objects, data.dim
    si, vi = fam.start_index, fam.velocity_index
    tau0 = st.tau[:, 0]
    u0 = st.u[:, 0]
    dt0 = (st.tbar[:, 0] - st.tbar[0, 0]) + (st.tcorr[:, 0] - st.tcorr[0, 0])
    sw = np.sqrt(data.w / np.mean(data.w) / (n * d))
    ts = float(np.max(np.abs(tau0))) or 1.0
    pairs = [(g[0], j) for g in fam.start_groups for j in g[1:]]
    if formulation == "reduced":
        lever, a = _anchors(st, fam, 0)
        col = lever[data.obj] + tau0
        tsr = float(np.max(np.abs(col))) or 1.0
        struct = _digest(data.obj, col / tsr, sw, si, vi)
    else:
        struct = _digest(data.obj, tau0 / ts, sw, dt0 / ts, u0 / ts, si, vi)
    key = (formulation, fam.start_groups, fam.velocity_groups, n, q, d, struct)
    model: Any = _MODELS.get(key)
    cached = model is not None
    if model is None:
        target = cp.Parameter((n, d), name="target")
        if formulation == "constrained":
            sel0 = sp.csr_matrix((np.ones(n), (np.arange(n), data.obj)), shape=(n, q))
            sel1 = sp.csr_matrix((tau0 / ts, (np.arange(n), data.obj)), shape=(n, q))
            pv = cp.Variable((q, d), name="position")
            v = cp.Variable((q, d), name="velocity")
            offs = cp.Parameter((max(len(pairs), 1), d), name="offsets")
            cons = []
            for g in fam.velocity_groups:
                if len(g) > 1:
                    cons.append(v[list(g[1:])] == np.ones((len(g) - 1, 1)) @ v[[g[0]]])
            for k, (r, j) in enumerate(pairs):
                if vi[j] == vi[r]:
                    cons.append(pv[j] - pv[r] + offs[k] == ((dt0[j] - dt0[r]) / ts) * v[r])
                else:
                    cons.append(
                        pv[j] - pv[r] + offs[k] == (u0[j] / ts) * v[j] - (u0[r] / ts) * v[r]
                    )
            obj = cp.sum_squares(cp.multiply(sw, target - sel0 @ pv - sel1 @ v))
            model = (cp.Problem(cp.Minimize(obj), cons), target, offs, (pv, v))
        else:
            rows = np.concatenate([np.arange(n), np.arange(n)])
            cols = np.concatenate([si[data.obj], vi[data.obj]])
            am = sp.csr_matrix(
                (np.concatenate([np.ones(n), col / tsr]), (rows, cols)), shape=(n, fam.n_params)
            )
            th = cp.Variable((fam.n_params, d), name="theta")
            obj = cp.sum_squares(cp.multiply(sw, target - am @ th))
            model = (cp.Problem(cp.Minimize(obj)), target, None, (th,))
        _MODELS[key] = model
        while len(_MODELS) > MODEL_CACHE_SIZE:
            _MODELS.popitem(last=False)
    else:
        _MODELS.move_to_end(key)
    prob, target, offs, variables = model

    if formulation == "constrained":
        off = st.p
        yo = data.y - off[data.obj]
        ys = (
            max(
                float(np.max(np.abs(yo))),
                float(np.max(np.abs(off - off[0]))),
                float(np.max(np.abs(st.vhat))) * ts,
            )
            or 1.0
        )

        def set_values() -> Any:
            target.value = yo / ys
            vals = np.zeros(offs.shape)
            for k, (r, j) in enumerate(pairs):
                vals[k] = (off[j] - off[r]) / ys
            offs.value = vals

            def back_c() -> tuple[FloatArray, Any]:
                pv, v = variables
                pl = np.asarray(pv.value) * ys + off
                vl = np.asarray(v.value) * ys / ts
                vel = np.vstack([vl[list(g)].mean(axis=0) for g in fam.velocity_groups])
                vj = vel[vi - len(fam.start_groups)]
                s = pl - vj * u0[:, None]
                theta = np.vstack([[s[list(g)].mean(axis=0) for g in fam.start_groups], vel])
                return theta, (pl, vl, u0[:, None], dt0)

            return back_c
    else:
        ns = len(fam.start_groups)
        grp_off = np.vstack([[np.mean(st.p[list(g)], axis=0)] for g in fam.start_groups])
        yo = data.y - grp_off[si[data.obj]]
        ys = float(np.max(np.abs(yo))) or 1.0

        def set_values() -> Any:
            target.value = yo / ys

            def back_r() -> tuple[FloatArray, Any]:
                thc = np.asarray(variables[0].value) * ys
                thc[ns:] /= tsr
                thc[:ns] += grp_off
                for gi, g in enumerate(fam.start_groups):
                    if a[gi] != 0.0:
                        thc[gi] -= a[gi] * thc[vi[g[0]]]
                return thc, None

            return back_r

    return prob, set_values, variables[0], cached


def solve(
    data: TrajectoryData,
    family: FamilyName | Family = "diverging",
    *,
    formulation: Literal["constrained", "reduced"] = "constrained",
    solver: str | None = None,
    reuse_model: bool = True,
    **solver_options: Any,
) -> TrajectorySolution:
    """Least squares of the family, written as is and solved by a CVXPY solver.

    Parameters
    ----------
    data : TrajectoryData
    family : "diverging", "parallel", "independent" or a :class:`Family`
    formulation : {"constrained", "reduced"}
        ``"constrained"``: the original problem -- ``Q`` lines (2Q·d variables, each line
        by its position at its object's mean time and its velocity) with the family's
        equality constraints; ``"reduced"``: (1) in θ with the design matrix A (starts of
        groups whose objects share a velocity taken at the group's mean time, then moved
        to the epoch).
    solver : str, optional
        Any installed CVXPY QP/conic solver; default Clarabel.
    reuse_model : bool
        ``True`` (default): the parametric (DPP) model, kept across calls on the same
        design (times, weights, family), so a repeated solve skips CVXPY's
        canonicalisation; solved without a warm start, so that each answer does not
        depend on the calls before it. ``False``: a fresh, non-parametric model.
    **solver_options
        Passed to the solver, over :data:`SOLVER_DEFAULTS` (an option the solver rejects
        is a ProblemError).

    Returns
    -------
    TrajectorySolution
        ``covariance`` is Ψ (14) at the data's design; ``residuals`` are the equality
        violations of the solver's lines and the stationarity (relative distance to the
        exact optimum), re-computed in NumPy in centred times. A claimed optimum above
        :data:`VERIFY_TOL` becomes OPTIMAL_INACCURATE (≤ :data:`REJECT_TOL`) or ERROR; a
        failed solve keeps its status and carries NaN estimates.

    Raises
    ------
    ProblemError
        Bad arguments, a numerically singular design, an epoch too far from the data.
    """
    as_instance("trajectories.solve data", data, TrajectoryData)
    fam = resolve_family(family, data.n_objects)
    form = as_choice("trajectories.solve formulation", formulation, ("constrained", "reduced"))
    if solver is None:
        name = "CLARABEL"
    elif isinstance(solver, str):
        name = solver.upper()
    else:
        raise ProblemError(
            f"trajectories.solve solver: expected a solver name (str), got {type(solver).__name__}"
        )
    opts = backend_options("lsq", name, solver_options)
    if not reuse_model:
        with timed() as tb:
            fit = _fit(data, fam)
            prob, back = _cvxpy_problem(data, fam, form)
        res = solve_problem(prob, name, **opts)
        first = prob.variables()[0]
        ok = res.status.ok and first.value is not None
        theta, lines = back() if ok else (None, None)
        cached = False
    else:
        with _MODELS_LOCK:
            with timed() as tb:
                fit = _fit(data, fam)
                prob, set_values, first, cached = _parametric_model(data, fam, form)
                back = set_values()
            res = solve_problem(prob, name, warm_start=False, **opts)
            ok = res.status.ok and first.value is not None
            theta, lines = back() if ok else (None, None)
    common = res.common()
    common["build_time"] += tb.elapsed
    common["method"] = f"{res.method} ({form}{', compiled model reused' if cached else ''})"
    if not ok:
        return _failure(data, fam, fit, {}, common, None)
    assert theta is not None
    if not np.all(np.isfinite(theta)):
        common["message"] += "; the solver returned non-finite values"
        return _failure(data, fam, fit, {}, common, None)
    return _finish_solve(data, fam, fit, theta, lines, common)
