"""Joint ML position of the two-site system (paper 003, the original problem): min_x
Σ_k ((z_k − z_k(x)) / σ_k)² from all three measurements, as one block-separable CasADi/
IPOPT NLP over T rows (built once per T and options, in the CasADi back-end's cache),
or by a vectorised Gauss-Newton cross-check in NumPy, each re-checked in NumPy (stationarity and the
Newton step in CRB units). :class:`JointMLMixin` is the base of
:class:`optmodels.fusion.two_site.TwoSiteSystem`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from optmodels.backends.casadi_backend import (
    NLP_CACHE,
    BuiltNlp,
    accept_precision_limit,
    cached_nlpsol,
    check_options,
    run_nlpsol,
)
from optmodels.core import (
    FloatArray,
    ProblemError,
    Solution,
    Status,
    Verdict,
    as_choice,
    finish,
)

if TYPE_CHECKING:
    from optmodels.fusion.two_site import TwoSiteSystem


@dataclass
class JointMLSolution(Solution):
    """Joint ML positions ``estimate`` (T, 2) from all three measurements, one per row
    of z, and the per-trial relative stationarity ``stationarity`` (T,)."""

    estimate: FloatArray = field(default_factory=lambda: np.empty((0, 2)))
    stationarity: FloatArray = field(default_factory=lambda: np.empty(0))


class JointMLMixin:
    """The joint ML of :class:`~optmodels.fusion.two_site.TwoSiteSystem` (its methods
    :meth:`joint_ml`, ``_whitened``, ``_gauss_newton``), kept here with its NLP and cache;
    TwoSiteSystem inherits them."""

    def joint_ml(  # type: ignore[misc]  # self: the subclass that inherits this mixin
        self: TwoSiteSystem,
        z: ArrayLike,
        *,
        x0: ArrayLike | None = None,
        method: Literal["ipopt", "gauss_newton"] = "ipopt",
        options: dict[str, Any] | None = None,
    ) -> JointMLSolution:
        """ML position from all three measurements (the original problem):
        min_x Σ_k ((z_k − z_k(x)) / σ_k)² for every row of z (T rows, T ≥ 1).

        ``method="ipopt"``: CasADi/IPOPT. The T rows are independent problems, solved as
        one block-separable NLP (2T variables, block-diagonal exact Hessian), each row's
        position scaled by its CRB RMS around the start. ``options`` go to IPOPT; an
        unknown or ill-typed one raises ProblemError naming it. ``method="gauss_newton"``:
        vectorised Gauss-Newton with step halving in NumPy (an independent
        implementation, used to cross-check IPOPT).

        Start: the triangulation (``x0``, (2,) or (T, 2), to override). Re-checked in
        NumPy per row, with :func:`optmodels.core.verified_status` of the worst row:

        * ``residuals["stationarity"]``: J_tᵀR⁻¹r_t relative to ‖J_t‖‖r_t‖ + 1 in whitened
          units;
        * ``residuals["newton_step"]``: the Gauss-Newton step to the stationary point in
          CRB units, √(gᵀ(JᵀR⁻¹J)⁻¹g), i.e. the distance to the optimum relative to the
          estimate's own standard deviation (infinite where the information is singular,
          on the baseline's extension: the estimate is then not an isolated optimum).

        Above 1e-6 the status is OPTIMAL_INACCURATE, above 1e-3 ERROR (estimate NaN).
        IPOPT stopping at its precision limit (Search_Direction_Becomes_Too_Small) is
        reported as OPTIMAL_INACCURATE if both checks pass at 1e-6, as ERROR otherwise.
        """
        fn = "fusion.TwoSiteSystem.joint_ml"
        zz = np.atleast_2d(self._z(z, f"{fn} z"))
        if zz.ndim != 2:
            raise ProblemError(f"{fn} z: expected (T, 3) measurements, got shape {zz.shape}")
        t = zz.shape[0]
        if t == 0:
            raise ProblemError(f"{fn} z: no measurements (0 rows)")
        method = as_choice(  # type: ignore[assignment]
            f"{fn} method", method, ("ipopt", "gauss_newton")
        )
        opts = check_options(options)
        if x0 is None:
            start = self.triangulate(zz)
            fallback = self.azimuth_range_difference(zz)
            start = np.where(np.isnan(start), fallback, start)
            mid = 0.5 * (self.site_a + self.site_b)
            start = np.where(np.isnan(start), mid + np.array([0.0, self.baseline]), start)
        else:
            p0 = self._pos(x0, f"{fn} x0")
            if p0.shape not in ((2,), (t, 2)):
                raise ProblemError(f"{fn} x0: expected (2,) or ({t}, 2), got {p0.shape}")
            self._off_sites(p0, f"{fn} x0")
            start = np.broadcast_to(p0, (t, 2)).astype(float)
        if method == "gauss_newton":
            est, common = self._gauss_newton(zz, start)
        else:
            # variables: x_t = start_t + L_t u_t with L_t the CRB RMS at the start, so that
            # the whitened objective has O(1) curvature in u whatever the noise level
            length = np.sqrt(np.trace(self._crb(start), axis1=-2, axis2=-1))
            length = np.where(np.isfinite(length) & (length > 0), length, self.baseline)
            built, _ = _joint_nlp(t, opts)
            params = np.concatenate(
                [
                    zz.reshape(-1, order="F"),
                    start.reshape(-1, order="F"),
                    length,
                    self.site_a,
                    self.site_b,
                    [self.sigma_azimuth, self.sigma_range_difference],
                ]
            )
            res, u = run_nlpsol(built, x0=np.zeros(2 * t), p=params)
            est = start + length[:, None] * u.reshape(t, 2, order="F")
            common = res.common()
        jw, wr, g, stat = self._whitened(zz, est)
        step = _newton_step(jw, g)
        worst_stat = float(np.max(stat))
        worst_step = float(np.max(step))
        worst = (
            max(worst_stat, worst_step) if np.isfinite(worst_stat + worst_step) else float("inf")
        )
        # IPOPT's precision limit (tiny noise makes the whitened problem stiff): accept the
        # point only because the NumPy stationarity check passes
        common["status"], common["message"] = accept_precision_limit(
            common["status"],
            common["message"],
            worst,
            f" (stationarity {worst:.1e} verified in NumPy)",
        )

        def note(v: Verdict) -> str:
            return (
                (
                    f"stationarity {worst_stat:.2g}, Newton step {worst_step:.2g} (CRB units)"
                    " fail the NumPy check"
                )
                if v.status == Status.ERROR and v.before.ok
                else ""
            )

        def no_estimate(sol: JointMLSolution) -> None:
            sol.estimate = np.full_like(sol.estimate, np.nan)
            sol.objective = float("nan")

        sol = JointMLSolution(
            objective=float(np.sum(wr**2)),
            residuals={"stationarity": worst_stat, "newton_step": worst_step},
            estimate=est,
            stationarity=stat,
            **common,
        )
        return finish(sol, note=note, reject=no_estimate)  # the one gate

    def _whitened(  # type: ignore[misc]
        self: TwoSiteSystem,
        z: FloatArray,
        x: FloatArray,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Whitened Jacobian (T, 3, 2), residuals (T, 3), gradient J_tᵀR⁻¹r_t (T, 2) and the
        relative stationarity ‖g_t‖ / (‖J_t‖‖r_t‖ + 1) per row, at positions x (NaN rows
        where x is not finite or at a site)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            jw = self._jac(x) / np.sqrt(np.diag(self.noise_cov))[:, None]
            r = self._residuals(z, x)
            g = np.einsum("tki,tk->ti", jw, r)
            stat = np.linalg.norm(g, axis=1) / (
                np.linalg.norm(jw, axis=(1, 2)) * np.linalg.norm(r, axis=1) + 1.0
            )
        return jw, r, g, np.where(np.isfinite(stat), stat, np.inf)

    def _gauss_newton(  # type: ignore[misc]
        self: TwoSiteSystem,
        z: FloatArray,
        start: FloatArray,
        max_iter: int = 50,
    ) -> tuple[FloatArray, dict[str, Any]]:
        """Vectorised Gauss-Newton with step halving; stops when every row's full step is
        below 1e-10 of the baseline or its relative stationarity (as in :meth:`joint_ml`)
        below 1e-10 (GN converges only linearly on non-zero residuals), or no step along
        its direction lowers the cost any more (round-off floor). A singular normal matrix
        (a row on the baseline's extension) ends the run with ERROR."""
        t0 = time.perf_counter()
        x = start.copy()
        cost = np.sum(self._residuals(z, x) ** 2, axis=1)
        it, converged = 0, False
        stalled = np.zeros(len(x), dtype=bool)
        for it in range(1, max_iter + 1):
            jw, _, g, stat = self._whitened(z, x)
            normal = np.swapaxes(jw, 1, 2) @ jw
            if not np.all(np.isfinite(normal)) or np.any(np.linalg.det(normal) <= 0):
                return x, {
                    "status": Status.ERROR,
                    "method": "gauss_newton",
                    "solve_time": time.perf_counter() - t0,
                    "iterations": it,
                    "message": "Gauss-Newton: singular normal matrix (degenerate geometry)",
                }
            step = np.linalg.solve(normal, g[..., None])[..., 0]
            done = (np.max(np.abs(step), axis=1) < 1e-10 * self.baseline) | (stat < 1e-10) | stalled
            if done.all():
                converged = True
                break
            lam = np.ones(len(x))
            for _ in range(30):
                trial = x + lam[:, None] * step
                new = np.sum(self._residuals(z, trial) ** 2, axis=1)
                worse = ~(new <= cost * (1 + 1e-12))  # round-off allowance
                if not worse.any():
                    break
                lam = np.where(worse, 0.5 * lam, lam)
            # no decrease even for tiny steps: the row is at its round-off floor
            stalled = lam < 2.0**-20
            x, cost = trial, new
        status = Status.OPTIMAL if converged else Status.ITERATION_LIMIT
        return x, {
            "status": status,
            "method": "gauss_newton",
            "solve_time": time.perf_counter() - t0,
            "iterations": it,
            "message": "Gauss-Newton",
        }


def _newton_step(jw: FloatArray, g: FloatArray) -> FloatArray:
    """√(gᵀ(JᵀJ)⁻¹g) per row (whitened J (T, 3, 2), g (T, 2)): the Gauss-Newton step in the
    metric of the Fisher information, i.e. in CRB standard deviations; inf where JᵀJ is
    singular or anything is not finite."""
    info = np.swapaxes(jw, 1, 2) @ jw
    a, b, d = info[:, 0, 0], info[:, 0, 1], info[:, 1, 1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        det = a * d - b * b
        q = (d * g[:, 0] ** 2 - 2 * b * g[:, 0] * g[:, 1] + a * g[:, 1] ** 2) / det
        ok = np.isfinite(q) & (det > 1e-14 * (a + d) ** 2)
        return np.where(ok, np.sqrt(np.abs(q)), np.inf)


#: The built joint-ML NLPs live in the CasADi back-end's one cache, under this namespace.
_CACHE_NAMESPACE = "fusion.joint_ml"


def _joint_nlp(t: int, options: dict[str, Any]) -> tuple[BuiltNlp, bool]:
    """Block-separable NLP of T joint-ML problems, variables u with x = start + L u
    (cached per T and options)."""
    return cached_nlpsol(_CACHE_NAMESPACE, (t,), lambda: _joint_problem(t), options=options)


def _joint_problem(t: int) -> dict[str, Any]:
    u = ca.MX.sym("u", t, 2)
    z = ca.MX.sym("z", t, 3)
    x0 = ca.MX.sym("x0", t, 2)
    length = ca.MX.sym("L", t)
    sa, sb = ca.MX.sym("A", 2), ca.MX.sym("B", 2)
    sig = ca.MX.sym("sig", 2)
    px = x0[:, 0] + length * u[:, 0]
    py = x0[:, 1] + length * u[:, 1]
    da_x, da_y = px - sa[0], py - sa[1]
    db_x, db_y = px - sb[0], py - sb[1]

    def wrap(a: Any) -> Any:
        return ca.atan2(ca.sin(a), ca.cos(a))

    ra = wrap(z[:, 0] - ca.atan2(da_x, da_y)) / sig[0]
    rb = wrap(z[:, 1] - ca.atan2(db_x, db_y)) / sig[0]
    rd = (z[:, 2] - (ca.sqrt(db_x**2 + db_y**2) - ca.sqrt(da_x**2 + da_y**2))) / sig[1]
    f = ca.sumsqr(ra) + ca.sumsqr(rb) + ca.sumsqr(rd)
    return {"x": ca.vec(u), "f": f / t, "p": ca.vertcat(ca.vec(z), ca.vec(x0), length, sa, sb, sig)}


def clear_joint_cache() -> None:
    """Forget the built joint-ML NLPs (the next solve pays the CasADi construction again;
    used by benchmarks that measure cold build + solve)."""
    NLP_CACHE.clear(_CACHE_NAMESPACE)
