"""The one verification gate (issue 15, item 3): every solve and closed form ends in
:func:`optmodels.core.finish` → :func:`optmodels.core.gate`, which re-checks the answer's
NumPy residuals and sets the status. Each test corrupts a solver's answer (the back-end
call) or a closed form's kernel by a small and by a large amount and sees it downgraded to
OPTIMAL_INACCURATE and refused (ERROR), the gate's own verdict being the status returned.
The residuals are compared with an independent computation of the perturbation."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import scipy.linalg

from optmodels import assignment as asg
from optmodels import biasfield as bf
from optmodels import core, plane
from optmodels import fusion as fu
from optmodels import trajectories as tr
from optmodels.backends import casadi_backend as cb
from optmodels.core import REJECT_TOL, VERIFY_TOL, Status, Verdict

SMALL, LARGE = Status.OPTIMAL_INACCURATE, Status.ERROR


@pytest.fixture
def verdicts(monkeypatch: pytest.MonkeyPatch) -> list[Verdict]:
    """Every verdict of the one gate during the test (a spy on core.gate)."""
    seen: list[Verdict] = []
    real = core.gate

    def spy(*args: Any, **kwargs: Any) -> Verdict:
        v = real(*args, **kwargs)
        seen.append(v)
        return v

    monkeypatch.setattr(core, "gate", spy)
    return seen


def decided(seen: list[Verdict], sol: core.Solution, expect: Status) -> None:
    """The gate was called once, on a claimed optimum, and its verdict is the status."""
    assert len(seen) == 1, seen
    v = seen[0]
    assert v.before.ok and v.changed
    assert v.status is expect is sol.status, sol.message


def rotate(n: np.ndarray, angle: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` (unit) turned by ``angle`` rad about a random axis orthogonal to it."""
    t = rng.normal(size=3)
    t -= (t @ n) * n
    t /= np.linalg.norm(t)
    return np.cos(angle) * n + np.sin(angle) * t


# --------------------------------------------------------------------------- plane
def plane_data(rng: np.random.Generator, n: int = 40) -> plane.PlaneData:
    normal = np.array([0.3, -0.5, 0.81])
    normal /= np.linalg.norm(normal)
    t = np.linalg.svd(normal[None])[2][1:]
    pts = 200.0 * rng.normal(size=(n, 2)) @ t + 50.0 * normal
    base = np.diag([1.0, 2.0, 0.5])
    alpha2 = rng.uniform(0.5, 2.0, n)
    pts = pts + np.sqrt(alpha2)[:, None] * rng.normal(size=(n, 3)) @ np.linalg.cholesky(base).T
    return plane.PlaneData(pts, base, alpha2)


def exact_normal(data: plane.PlaneData) -> np.ndarray:
    """ML normal under (1.4) by scipy's generalized eigensolver on (Q, D)."""
    q = plane.scatter_matrix(data)
    _, vecs = scipy.linalg.eigh(q, data.base_cov)
    n = vecs[:, 0]
    return n / np.linalg.norm(n)


def angle(a: np.ndarray, b: np.ndarray) -> float:
    c = abs(float(a @ b)) / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.arccos(min(1.0, c)))


@pytest.mark.parametrize(("turn", "expect"), [(1e-5, SMALL), (1e-2, LARGE)])
def test_plane_solve_corrupted_point(
    monkeypatch: pytest.MonkeyPatch, verdicts: list[Verdict], turn: float, expect: Status
) -> None:
    rng = np.random.default_rng(1)
    data = plane_data(rng)
    real = plane.generic.run_nlpsol

    def corrupted(*args: Any, **kwargs: Any) -> tuple[Any, np.ndarray]:
        res, x = real(*args, **kwargs)
        x = x.copy()
        x[:3] = rotate(x[:3] / np.linalg.norm(x[:3]), turn, rng)
        return res, x

    monkeypatch.setattr(plane.generic, "run_nlpsol", corrupted)
    sol = plane.solve(data, "reduced", starts=1)
    decided(verdicts, sol, expect)
    # a refused plane carries no estimate; the corrupted point is kept for diagnosis
    normal = sol.normal if sol.ok else sol.info["rejected"]["normal"]
    assert sol.ok or np.all(np.isnan(sol.normal))
    err = angle(normal, exact_normal(data))
    assert err == pytest.approx(turn, rel=0.05)
    # the re-check estimates the distance to the optimum: the Newton step ≈ the turn
    assert sol.info["verification"]["stationarity"] == pytest.approx(err, rel=0.05)


@pytest.mark.parametrize(("how", "expect"), [("turn", SMALL), ("stretch", LARGE)])
def test_plane_closed_form_corrupted_kernel(
    monkeypatch: pytest.MonkeyPatch, verdicts: list[Verdict], how: str, expect: Status
) -> None:
    """Small: the kernel's normal turned by 1e-5 rad (re-checked by the kernel's own
    Rayleigh step); large: its length 1.01 (‖n‖² − 1 = 0.0201), since a turn the Newton
    step measures above 1e-3 rad is refused with a ProblemError before the gate."""
    rng = np.random.default_rng(2)
    data = plane_data(rng)
    mod = plane.closedform
    real = mod._closed_form_from_sums

    def corrupted(s0: Any, s1: Any, s2: Any, s2abs: Any, count: Any, base: Any) -> Any:
        eig = real(s0, s1, s2, s2abs, count, base)
        if how == "stretch":
            return dataclasses.replace(eig, normal=1.01 * eig.normal)
        n = rotate(eig.normal[0], 1e-5, rng)[None]
        q = s2 - s1[..., :, None] * s1[..., None, :] / s0[..., None, None]
        qabs = s2abs + np.abs(s1)[..., :, None] * np.abs(s1)[..., None, :] / s0[..., None, None]
        return dataclasses.replace(
            eig, normal=n, check=plane.verify._rayleigh_check(q, qabs, base, n, count)
        )

    monkeypatch.setattr(mod, "_closed_form_from_sums", corrupted)
    sol = plane.closed_form(data)
    decided(verdicts, sol, expect)
    checks = sol.info["verification"]
    if how == "turn":
        err = angle(sol.normal, exact_normal(data))
        assert err == pytest.approx(1e-5, rel=0.05)
        assert checks["stationarity"] == pytest.approx(err, rel=0.05)
    else:
        assert checks["unit_normal"] == pytest.approx(1.01**2 - 1, rel=1e-9)


# --------------------------------------------------------------------------- trajectories
def trajectory_data(rng: np.random.Generator) -> tr.TrajectoryData:
    times = [np.sort(rng.uniform(0, 60, 25)) for _ in range(3)]
    v = np.array([3.0, -2.0, 5.0])
    vals = [100.0 + vj * t + rng.normal(0, 1.0, t.size) for vj, t in zip(v, times, strict=True)]
    return tr.TrajectoryData(times, vals, 1.0)


def _shift_velocity(theta: np.ndarray, fam: tr.Family, rel: float) -> tuple[np.ndarray, float]:
    th = np.array(theta, dtype=float, copy=True)
    size = float(np.max(np.abs(th[len(fam.start_groups) :])))
    th[fam.velocity_index[0]] += rel * size
    return th, size


@pytest.mark.parametrize(("rel", "expect"), [(1e-5, SMALL), (1e-2, LARGE)])
def test_trajectories_closed_form_corrupted_kernel(
    monkeypatch: pytest.MonkeyPatch, verdicts: list[Verdict], rel: float, expect: Status
) -> None:
    data = trajectory_data(np.random.default_rng(3))
    fam = tr.resolve_family("diverging", data.n_objects)
    honest = tr.closed_form(data)
    verdicts.clear()
    mod = tr.closedform
    real = mod._fit

    def corrupted(*args: Any, **kwargs: Any) -> Any:
        fit = real(*args, **kwargs)
        return dataclasses.replace(fit, theta=_shift_velocity(fit.theta, fam, rel)[0])

    monkeypatch.setattr(mod, "_fit", corrupted)
    sol = tr.closed_form(data)
    decided(verdicts, sol, expect)
    # the Newton step is exact for least squares: the stationarity is the shift itself,
    # relative to the largest velocity (which dominates its standard deviation here)
    size = float(np.max(np.abs(honest.velocity)))
    assert sol.residuals["stationarity"] == pytest.approx(rel, rel=1e-3)
    if expect is LARGE:
        assert np.all(np.isnan(sol.theta))
        assert sol.info["rejected_theta"][fam.velocity_index[0], 0] == pytest.approx(
            honest.velocity[0] + rel * size, rel=1e-9
        )
    else:
        assert sol.velocity[0] == pytest.approx(honest.velocity[0] + rel * size, rel=1e-9)


@pytest.mark.parametrize("reuse", [False, True])
@pytest.mark.parametrize(("rel", "expect"), [(1e-5, SMALL), (1e-2, LARGE)])
def test_trajectories_solve_corrupted_point(
    monkeypatch: pytest.MonkeyPatch,
    verdicts: list[Verdict],
    rel: float,
    expect: Status,
    reuse: bool,
) -> None:
    """The solver's θ shifted: downgraded, then refused. The decision is the strict gate
    of :func:`optmodels.trajectories.verify._finish_solve` (the same point through it
    gives the same solution); ``generic.solve`` still decides inline until it calls that
    function (see the gate slice's report)."""
    data = trajectory_data(np.random.default_rng(4))
    fam = tr.resolve_family("diverging", data.n_objects)
    gen = tr.generic
    real = gen._cvxpy_problem
    seen: dict[str, Any] = {}

    def corrupted(*args: Any, **kwargs: Any) -> Any:
        prob, back = real(*args, **kwargs)

        def bad_back() -> Any:
            theta, lines = back()
            seen["theta"] = _shift_velocity(theta, fam, rel)[0]
            return seen["theta"], lines

        return prob, bad_back

    real_parametric = gen._parametric_model

    def corrupted_parametric(*args: Any, **kwargs: Any) -> Any:
        prob, set_values, first, cached = real_parametric(*args, **kwargs)

        def bad_set_values() -> Any:
            back = set_values()

            def bad_back() -> Any:
                theta, lines = back()
                seen["theta"] = _shift_velocity(theta, fam, rel)[0]
                return seen["theta"], lines

            return bad_back

        return prob, bad_set_values, first, cached

    # both paths: the fresh model and the compiled (DPP) model kept between solves
    monkeypatch.setattr(gen, "_cvxpy_problem", corrupted)
    monkeypatch.setattr(gen, "_parametric_model", corrupted_parametric)
    sol = tr.solve(data, formulation="reduced", reuse_model=reuse)
    assert sol.status is expect, sol.message
    assert sol.residuals["stationarity"] == pytest.approx(rel, rel=1e-2)
    verdicts.clear()
    common = {"status": Status.OPTIMAL, "method": sol.method, "message": "", "solve_time": 0.0}
    via_gate = tr.verify._finish_solve(
        data, fam, tr.fits._fit(data, fam), seen["theta"], None, common
    )
    decided(verdicts, via_gate, expect)
    assert via_gate.residuals == pytest.approx(sol.residuals, rel=1e-6, abs=1e-12)


# --------------------------------------------------------------------------- fusion
def spd(rng: np.random.Generator, m: int) -> np.ndarray:
    a = rng.normal(size=(m, m))
    return a @ a.T + m * np.eye(m)


@pytest.mark.parametrize(("eps", "expect"), [(1e-5, SMALL), (1e-1, LARGE)])
def test_fusion_closed_form_corrupted_kernel(
    monkeypatch: pytest.MonkeyPatch, verdicts: list[Verdict], eps: float, expect: Status
) -> None:
    rng = np.random.default_rng(5)
    m = 3
    s1, s2 = spd(rng, m), spd(rng, m)
    a1, a2 = rng.normal(size=m), rng.normal(size=m)
    w_exact = np.linalg.solve(s1 + s2, s1.T).T  # W (2): W (S1 + S2) = S1
    real = fu.closedform._weight

    def corrupted(x: Any, y: Any) -> np.ndarray:
        w = real(x, y)
        return w + eps * float(np.max(np.abs(w))) * np.eye(m)

    monkeypatch.setattr(fu.closedform, "_weight", corrupted)
    sol = fu.fuse(a1, s1, a2, s2)
    decided(verdicts, sol, expect)
    # the actual relative error of W is eps (independently: W_exact by np.linalg.solve);
    # the residual is a forward error bound: above it, not by more than the conditioning
    w_bad = corrupted(s1, s2)
    actual = float(np.max(np.abs(w_bad - w_exact)) / np.max(np.abs(w_exact)))
    assert actual == pytest.approx(eps, rel=1e-6)
    assert actual <= sol.residuals["weight_error"] <= 30 * actual
    if expect is LARGE:  # the failure form: no estimate, and no W once W itself failed
        assert np.all(np.isnan(sol.estimate)) and np.all(np.isnan(sol.W))
    else:
        assert np.allclose(sol.W, w_bad, rtol=0, atol=1e-15)
        assert np.allclose(sol.estimate, a1 + w_bad @ (a2 - a1), rtol=1e-12)


@pytest.mark.parametrize(("eps", "expect"), [(1e-5, SMALL), (1e-1, LARGE)])
def test_fusion_cvxpy_corrupted_point(
    monkeypatch: pytest.MonkeyPatch, verdicts: list[Verdict], eps: float, expect: Status
) -> None:
    rng = np.random.default_rng(6)
    m = 3
    s1, s2 = spd(rng, m), spd(rng, m)
    a1, a2 = rng.normal(size=m), rng.normal(size=m)
    c1, c2 = np.linalg.inv(s1), np.linalg.inv(s2)
    exact = np.linalg.solve(c1 + c2, c1 @ a1 + c2 @ a2)  # (1), independently
    real = fu.generic.solve_problem
    d = float(np.max(np.abs(a2 - a1)))

    def corrupted(prob: Any, *args: Any, **kwargs: Any) -> Any:
        res = real(prob, *args, **kwargs)
        (u,) = prob.variables()
        u.value = u.value + eps * float(np.max(np.abs(exact))) / d * np.ones(m)
        return res

    monkeypatch.setattr(fu.generic, "solve_problem", corrupted)
    sol = fu.fuse(a1, s1, a2, s2, method="cvxpy")
    decided(verdicts, sol, expect)
    size = max(np.max(np.abs(exact)), np.max(np.abs(a1)), np.max(np.abs(a2)))
    bound = sol.residuals["estimate_error"]
    assert eps * np.max(np.abs(exact)) / size * 0.99 <= bound <= 30 * eps
    assert np.all(np.isnan(sol.estimate)) == (expect is LARGE)


# --------------------------------------------------------------------------- bias field
@pytest.fixture(scope="module")
def field_data() -> bf.FieldData:
    fd, _ = bf.synthetic_field_data(7, cells=30)
    return fd


def _kkt_gradient(data: bf.FieldData, phi: np.ndarray) -> float:
    """Φ¹ᵀRφ relative to Φ¹ᵀRΦ⁰, recomputed here from the public sets and R."""
    phi0, phi1 = bf.uncertainty_sets(data)
    r = bf.problem.r_matrix(data)
    return float(np.max(np.abs(phi1.T @ (r @ phi)))) / float(np.max(np.abs(phi1.T @ (r @ phi0))))


@pytest.mark.parametrize(("eps", "expect"), [(1e-5, SMALL), (1e-1, LARGE)])
def test_biasfield_closed_form_corrupted_kernel(
    monkeypatch: pytest.MonkeyPatch,
    verdicts: list[Verdict],
    field_data: bf.FieldData,
    eps: float,
    expect: Status,
) -> None:
    honest = bf.closed_form(field_data)
    verdicts.clear()
    mod = bf.closedform
    real = mod.splinalg.splu

    class Bad:
        def __init__(self, lu: Any) -> None:
            self.lu = lu

        def solve(self, b: np.ndarray, trans: str = "N") -> np.ndarray:
            return self.lu.solve(b, trans=trans) * (1 + eps)

        def __getattr__(self, name: str) -> Any:
            return getattr(self.lu, name)

    monkeypatch.setattr(mod.splinalg, "splu", lambda a: Bad(real(a)))
    sol = bf.closed_form(field_data)
    decided(verdicts, sol, expect)
    # η* scaled by 1 + ε: the gradient Φ¹ᵀR(Φ⁰ + (1+ε)Φ¹η*) = ε Φ¹ᵀRΦ¹η* = −ε Φ¹ᵀRΦ⁰
    assert sol.residuals["stationarity"] == pytest.approx(eps, rel=1e-3)
    if expect is LARGE:
        assert np.all(np.isnan(sol.field))
    else:
        assert _kkt_gradient(field_data, sol.phi) == pytest.approx(eps, rel=1e-3)
        assert np.allclose(sol.eta, (1 + eps) * honest.eta, rtol=1e-9, atol=0)


def _scale_variables(real: Callable[..., Any], factor: float) -> Callable[..., Any]:
    def corrupted(where: str, prob: Any, *args: Any) -> Any:
        res = real(where, prob, *args)
        for v in prob.variables():
            if v.value is not None and v.name().startswith(("eta", "var")):
                v.value = v.value * factor
        return res

    return corrupted


@pytest.mark.parametrize(("eps", "expect"), [(1e-5, SMALL), (1e-1, LARGE)])
def test_biasfield_solve_corrupted_point(
    monkeypatch: pytest.MonkeyPatch,
    verdicts: list[Verdict],
    field_data: bf.FieldData,
    eps: float,
    expect: Status,
) -> None:
    honest = bf.closed_form(field_data)
    verdicts.clear()
    monkeypatch.setattr(bf.problem, "run_solver", _scale_variables(bf.problem.run_solver, 1 + eps))
    sol = bf.solve(field_data)
    decided(verdicts, sol, expect)
    assert sol.residuals["stationarity"] == pytest.approx(eps, rel=1e-2)
    if expect is SMALL:
        assert np.allclose(
            sol.eta, (1 + eps) * honest.eta, rtol=1e-5, atol=1e-6 * np.max(np.abs(honest.eta))
        )
    else:
        assert np.all(np.isnan(sol.field))


@pytest.mark.parametrize(("eps", "expect"), [(1e-5, SMALL), (1e-1, LARGE)])
def test_biasfield_lipschitz_corrupted_point(
    monkeypatch: pytest.MonkeyPatch,
    verdicts: list[Verdict],
    field_data: bf.FieldData,
    eps: float,
    expect: Status,
) -> None:
    monkeypatch.setattr(bf.problem, "run_solver", _scale_variables(bf.problem.run_solver, 1 + eps))
    sol = bf.solve_lipschitz(field_data)
    decided(verdicts, sol, expect)
    assert (
        REJECT_TOL >= sol.max_residual > VERIFY_TOL
        if expect is SMALL
        else sol.max_residual > REJECT_TOL
    )
    assert np.all(np.isnan(sol.field)) == (expect is LARGE)


# --------------------------------------------------------------------------- assignment
def assignment_case(rng: np.random.Generator, q: int = 4, n: int = 4) -> asg.AssignmentData:
    means = rng.uniform(0, 3.0, (q, 2))
    covs = np.stack([np.eye(2) * rng.uniform(0.1, 0.5) for _ in range(q)])
    meas = rng.uniform(0, 3.0, (n, 2))
    meas[:q] = means[:n] + rng.normal(0, 0.5, (n, 2))
    return asg.AssignmentData(means, covs, meas, 0.25 * np.eye(2), 9.0, 0.9, 0.3)


@pytest.mark.parametrize(("rel", "expect"), [(1e-5, SMALL), (1e-2, LARGE)])
def test_assignment_solve_corrupted_point(
    monkeypatch: pytest.MonkeyPatch, verdicts: list[Verdict], rel: float, expect: Status
) -> None:
    """The MILP's objective off by ``rel``: downgraded, then refused, by the gate of
    :func:`optmodels.assignment.verify._finish` (the same point through it gives the
    same solution); ``milp.solve`` still decides inline until it calls that function (see
    the gate slice's report)."""
    data = assignment_case(np.random.default_rng(9))
    honest = asg.solve(data, model="cvxpy")
    assert honest.status is Status.OPTIMAL and abs(honest.log_score) > 1.0
    real = asg.milp.solve_problem

    def corrupted(prob: Any, *args: Any, **kwargs: Any) -> Any:
        res = real(prob, *args, **kwargs)
        return dataclasses.replace(res, objective=res.objective * (1 + rel))

    monkeypatch.setattr(asg.milp, "solve_problem", corrupted)
    captured: dict[str, Any] = {}
    real_recheck = asg.verify._recheck

    def spy_recheck(*args: Any) -> Any:
        captured["args"] = args
        return real_recheck(*args)

    # the re-check's inputs, whether milp.solve calls _recheck itself or verify._finish does
    monkeypatch.setattr(asg.milp, "_recheck", spy_recheck, raising=False)
    monkeypatch.setattr(asg.verify, "_recheck", spy_recheck)
    sol = asg.solve(data, model="cvxpy")
    assert sol.status is expect, sol.message
    assert sol.residuals["objective"] == pytest.approx(rel, rel=1e-6)
    verdicts.clear()
    common = {
        "status": Status.OPTIMAL,
        "method": sol.method,
        "message": "",
        "build_time": 0.0,
        "solve_time": 0.0,
        "iterations": None,
    }
    via_gate = asg.verify._finish(
        *captured["args"], common=common, gap_reached=None, gap=0.0, info={}
    )
    decided(verdicts, via_gate, expect)
    assert via_gate.partition == sol.partition
    assert via_gate.residuals == sol.residuals


@pytest.mark.parametrize(("rel", "expect"), [(1e-5, SMALL), (1e-2, LARGE)])
def test_assignment_linear_corrupted_kernel(
    monkeypatch: pytest.MonkeyPatch, verdicts: list[Verdict], rel: float, expect: Status
) -> None:
    """The gains (kernel input of scipy's linear_sum_assignment) shifted so that the
    assignment's total disagrees with the recomputed score (13) by ``rel``."""
    rng = np.random.default_rng(10)
    means = rng.uniform(0, 40, (5, 2))
    meas = np.vstack([means + rng.normal(0, 0.3, (5, 2)), rng.uniform(0, 40, (1, 2))])
    data = asg.AssignmentData(
        means, np.stack([np.eye(2)] * 5), meas, 0.25 * np.eye(2), 1600.0, 0.9, 0.3, max_group_size=1
    )
    honest = asg.linear_assignment(data)
    assert honest.status is Status.OPTIMAL
    verdicts.clear()
    scale = max(1.0, abs(honest.log_score))
    real = asg.linear.log_likelihoods

    def corrupted(d: Any, groups: Any) -> np.ndarray:
        # every gain up by the same amount: the optimal assignment stays, its total moves
        # by (number of assigned measurements) × shift
        return real(d, groups) + rel * scale / max(1, int(np.sum(honest.assignment >= 0)))

    monkeypatch.setattr(asg.linear, "log_likelihoods", corrupted)
    sol = asg.linear_assignment(data)
    decided(verdicts, sol, expect)
    assert sol.residuals["objective"] == pytest.approx(rel, rel=1e-6)
    if expect is SMALL:
        assert list(sol.assignment) == list(honest.assignment)
    else:
        assert sol.partition == [] and np.isnan(sol.objective)


# --------------------------------------------------------------------------- the pieces
def test_gate_thresholds_and_strict_form() -> None:
    g = core.gate
    ok, inacc = Status.OPTIMAL, Status.OPTIMAL_INACCURATE
    assert g(ok, {"a": 1e-7, "b": 0.0}).status is ok
    v = g(ok, {"a": 1e-7, "b": 2e-6})
    assert v.status is inacc and v.key == "b" and v.worst == 2e-6
    assert g(ok, {"a": float("nan"), "b": 0.0}).status is Status.ERROR
    assert g(ok, {"a": 2e-3}).status is Status.ERROR
    assert g(ok, {"dual_sign": 0.5}, ignore=("dual_sign",)).status is ok
    assert g(inacc, {"a": 2e-6}).status is inacc
    assert g(inacc, {"a": 2e-6}, strict=True).status is Status.ERROR
    assert g(Status.ITERATION_LIMIT, {"a": 1.0}).status is Status.ITERATION_LIMIT
    bad = core.failure(plane.PlaneSolution, "m", "why", status=Status.OPTIMAL)
    assert bad.status is Status.ERROR and np.isnan(bad.objective) and np.all(np.isnan(bad.normal))


def test_one_nlp_cache_and_precision_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    """plane and fusion share the back-end's cache; each clear function forgets only its
    own builds; IPOPT's precision limit is accepted only under VERIFY_TOL."""
    rng = np.random.default_rng(11)
    plane.clear_nlp_cache()
    fu.clear_joint_cache()
    sol = plane.solve(plane_data(rng, 12), "reduced", starts=1)
    assert sol.ok and not sol.info["cached_build"]
    assert plane.solve(plane_data(rng, 12), "reduced", starts=1).info["cached_build"]
    sys_ = fu.TwoSiteSystem.on_baseline()
    assert sys_.joint_ml(sys_.sample(np.array([8_000.0, 30_000.0]), 3, rng)).ok
    spaces = {k[0] for k in cb.NLP_CACHE.keys()}
    assert spaces >= {"plane", "fusion.joint_ml"}
    fu.clear_joint_cache()
    assert {k[0] for k in cb.NLP_CACHE.keys()} == {"plane"}
    plane.clear_nlp_cache()
    assert cb.NLP_CACHE.keys("plane") == []
    lim = cb.PRECISION_LIMIT
    assert cb.accept_precision_limit(Status.ERROR, lim, 5e-7, " ok") == (
        Status.OPTIMAL_INACCURATE,
        lim + " ok",
    )
    assert cb.accept_precision_limit(Status.ERROR, lim, 2e-6, " ok") == (Status.ERROR, lim)
    assert cb.accept_precision_limit(Status.ERROR, "Other", 0.0, " ok") == (Status.ERROR, "Other")
