"""Robustness sweep: every public entry point fed malformed and extreme inputs.

Each property accepts exactly two outcomes: a documented ``optmodels`` exception
(:class:`~optmodels.core.OptModelsError`: ProblemError for bad input, SolveError /
SolverNotAvailable for solver trouble), or a solution that either has an OK status **and**
small residuals against the original problem, or a non-OK status (a reported failure,
which ``require_ok`` turns into SolveError). Anything else -- a NumPy/SciPy/CVXPY/CasADi
exception leaking out, a NaN reported as an optimum, a residual above tolerance -- fails.

Inputs mix shapes (wrong and right), NaN/inf, scales from 1e-150 to 1e150, near-singular
and indefinite covariances, duplicate points and empty sets. 100 examples per entry point
in the default run; the ``slow`` twin of each runs 1000 (``make test-all``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import event as _hypothesis_event
from hypothesis import strategies as st
from hypothesis.control import currently_in_test_context

from optmodels import assignment as asg
from optmodels import biasfield as bf
from optmodels import fusion as fu
from optmodels import montecarlo as mc
from optmodels import plane
from optmodels import trajectories as tr
from optmodels.core import OptModelsError, Solution

#: Residual tolerance for an OK solution. The package's residuals are relative (scaled by
#: the data), so 1e-6 leaves ample room over the solvers' 1e-8..1e-10 accuracy while
#: catching any real violation.
RES_TOL = 1e-6

# ----------------------------------------------------------------------- strategies
SCALES = st.sampled_from([1e-150, 1e-12, 1e-3, 1.0, 1e3, 1e12, 1e150])
BAD = st.sampled_from([np.nan, np.inf, -np.inf])


@st.composite
def arrays(draw: st.DrawFn, shape: tuple[int, ...], *, bad: float = 0.03) -> np.ndarray:
    """Gaussian values at a random scale, sometimes with an offset, a duplicate-row
    pattern or a NaN/inf."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    x = rng.normal(size=shape) * draw(SCALES)
    if x.size and draw(st.booleans()):
        x = x + draw(SCALES)
    if x.ndim >= 1 and x.shape[0] > 1 and draw(st.floats(0, 1)) < 0.1:
        x[:] = x[0]  # every row the same (degenerate geometry)
    if x.size and draw(st.floats(0, 1)) < bad:
        x.flat[draw(st.integers(0, x.size - 1))] = draw(BAD)
    return x


@st.composite
def covariances(draw: st.DrawFn, m: int, count: int | None = None) -> np.ndarray:
    """SPD, near-singular, singular, indefinite or non-symmetric m×m matrices."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    kind = draw(st.sampled_from(["spd"] * 5 + ["near", "singular", "indefinite", "asym", "bad"]))
    n = 1 if count is None else count
    a = rng.normal(size=(n, m, m))
    c = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(m)
    if kind == "near":
        u = rng.normal(size=(n, m, 1))
        c = u @ u.transpose(0, 2, 1) + 1e-14 * np.eye(m)
    elif kind == "singular":
        u = rng.normal(size=(n, m, 1))
        c = u @ u.transpose(0, 2, 1)
    elif kind == "indefinite":
        c = c - 5 * np.trace(c, axis1=1, axis2=2)[:, None, None] * np.eye(m)
    elif kind == "asym":
        c = c + np.triu(np.ones((m, m)), 1)
    elif kind == "bad" and n:
        c[0, 0, 0] = draw(BAD)
    c = c * draw(SCALES)
    return c[0] if count is None else c


def event(text: str) -> None:
    """Hypothesis's ``event`` inside a property; nothing when ``accept`` serves a plain
    (parametrized) test."""
    if currently_in_test_context():
        _hypothesis_event(text)


def accept(fn: Callable[[], Any], tol: float = RES_TOL, scale: float = 1.0) -> None:
    """The property: a documented exception, or an honest solution."""
    try:
        out = fn()
    except OptModelsError as exc:
        event(f"refused: {type(exc).__name__}")
        return
    sols = out if isinstance(out, tuple | list) else [out]
    for sol in sols:
        if isinstance(sol, Solution):
            event(f"solution: {sol.status.value}")
            if sol.ok:
                assert np.isfinite(sol.objective), sol
                # OPTIMAL_INACCURATE is the packages' flag for a re-check between 1e-6 and
                # 1e-3 (above that: ERROR); OPTIMAL must meet ``tol``
                limit = tol if sol.status.value == "optimal" else 1e-3
                # (a bias field's max_residual leaves out its 'dual_sign' diagnostic)
                assert sol.max_residual <= limit * max(scale, 1.0), (sol.method, sol.residuals)
        elif isinstance(sol, np.ndarray):
            assert np.all(np.isfinite(sol)), "a NaN/inf result without an exception"


def sweep(
    prop: Callable[..., None], **strategies: Any
) -> tuple[Callable[..., None], Callable[..., None]]:
    """A default-run test (100 examples) and its ``slow`` twin (1000) of ``prop``."""
    common = {
        "deadline": None,
        "derandomize": True,
        "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
    }
    fast = settings(max_examples=100, **common)(given(**strategies)(prop))
    slow = pytest.mark.slow(settings(max_examples=1000, **common)(given(**strategies)(prop)))
    return fast, slow


# ----------------------------------------------------------------------------- plane
def _plane(data: st.DataObject, n: int, d: int, per_point: bool, method: str) -> None:
    pts = data.draw(arrays((n, d)))
    cov = data.draw(covariances(3, n if per_point else None))
    alpha2 = (
        None
        if per_point or not data.draw(st.booleans())
        else np.abs(data.draw(arrays((n,), bad=0.05))) + 0.0
    )

    def go() -> Any:
        pd = plane.PlaneData(pts, cov, alpha2)
        if method == "closed_form":
            return plane.closed_form(pd)
        if method == "svd":
            return plane.svd_fit(pd)
        return plane.solve(pd, method, starts=1)  # type: ignore[arg-type]

    # the (1.3) residual is in metres: round-off scales with the coordinates
    big = float(np.max(np.abs(pts))) if pts.size and np.all(np.isfinite(pts)) else 1.0
    accept(go, scale=big)


test_plane, test_plane_slow = sweep(
    _plane,
    data=st.data(),
    n=st.integers(0, 12),
    d=st.sampled_from([3, 3, 3, 2]),
    per_point=st.booleans(),
    method=st.sampled_from(["closed_form", "reduced", "full", "svd"]),
)


# ---------------------------------------------------------------------- trajectories
def _trajectories(data: st.DataObject, q: int, n: int, family: str, method: str) -> None:
    times = [data.draw(arrays((n,), bad=0.05)) for _ in range(q)]
    if data.draw(st.booleans()):
        times = [np.sort(np.abs(t)) for t in times]
    vals = [
        data.draw(arrays((n,) if data.draw(st.floats(0, 1)) < 0.9 else (n + 1,))) for _ in range(q)
    ]
    sigma2 = data.draw(st.sampled_from([1.0, 0.0, -1.0, np.nan, 1e-300, 1e300]))

    def go() -> Any:
        d = tr.TrajectoryData(times, vals, sigma2)
        if method == "closed_form":
            return tr.closed_form(d, family)  # type: ignore[arg-type]
        if method == "test":
            return tr.family_test(d, family)  # type: ignore[arg-type]
        return tr.solve(d, family, solver=method)  # type: ignore[arg-type]

    accept(go)


test_trajectories, test_trajectories_slow = sweep(
    _trajectories,
    data=st.data(),
    q=st.integers(0, 4),
    n=st.integers(0, 6),
    family=st.sampled_from(["diverging", "parallel", "independent"]),
    method=st.sampled_from(["closed_form", "CLARABEL", "test"]),
)


# ---------------------------------------------------------------------------- fusion
def _fusion(data: st.DataObject, m: int, m2: int, method: str, n: int) -> None:
    s1 = data.draw(covariances(m))
    s2 = data.draw(covariances(m2 if data.draw(st.floats(0, 1)) < 0.2 else m))
    a1, a2 = data.draw(arrays((m,))), data.draw(arrays((m,)))

    def go() -> Any:
        if method == "fuse":
            return fu.fuse(a1, s1, a2, s2)
        if method == "fuse_cvxpy":
            return fu.fuse(a1, s1, a2, s2, method="cvxpy")
        if method == "correlated":
            s12 = data.draw(arrays((m, m)))
            return fu.fuse(a1, s1, a2, s2, s12=s12)
        if method == "weight":
            return fu.weight_matrix(s1, s2)
        if method == "weight_covariance":
            return fu.weight_covariance(s1, s2, n, n, mean="sample")
        x1, x2 = data.draw(arrays((max(n, 0), m))), data.draw(arrays((max(n, 0), m)))
        return fu.weight_from_samples(x1, x2)

    accept(go)


test_fusion, test_fusion_slow = sweep(
    _fusion,
    data=st.data(),
    m=st.integers(1, 4),
    m2=st.integers(1, 4),
    method=st.sampled_from(
        ["fuse", "fuse_cvxpy", "correlated", "weight", "weight_covariance", "from_samples"]
    ),
    n=st.integers(-1, 8),
)


# ------------------------------------------------------------------------- biasfield
_BASE_FIELD = bf.synthetic_field_data(0, cells=12)[0]


def _biasfield(data: st.DataObject, what: str, box: Any, method: str) -> None:
    base = _BASE_FIELD
    fields: dict[str, Any] = {
        "radars": base.radars,
        "centers": base.centers,
        "xi": base.xi,
        "P": base.P,
        "adjacency": base.adjacency,
    }
    old = fields[what].toarray() if hasattr(fields[what], "toarray") else np.asarray(fields[what])
    shape = old.shape if data.draw(st.floats(0, 1)) < 0.8 else (*old.shape[:-1], 7)
    new = data.draw(arrays(shape, bad=0.2))
    if what == "adjacency":
        new = (np.abs(new) > 1).astype(float)
    elif what == "P" and shape == old.shape:
        new = data.draw(covariances(old.shape[0]))
    fields[what] = new

    def go() -> Any:
        d = bf.FieldData(**fields)
        if method == "closed_form":
            return bf.closed_form(d) if box is None else bf.solve(d, box=box)
        if method == "lipschitz":
            return bf.solve_lipschitz(d, box=box)
        return bf.solve(d, box=box, solver=method)

    # selection residuals are KKT/feasibility residuals relative to the data's scale
    accept(go, tol=1e-5)


test_biasfield, test_biasfield_slow = sweep(
    _biasfield,
    data=st.data(),
    what=st.sampled_from(["xi", "centers", "P", "adjacency", "radars"]),
    box=st.sampled_from([None, (1.0, 1e-3), (0.0, 0.0), (-1.0, 1.0), (np.nan, 1.0), (1e9, 1.0)]),
    method=st.sampled_from(["closed_form", "CLARABEL", "lipschitz"]),
)


# ------------------------------------------------------------------------ assignment
def _assignment(
    data: st.DataObject, q: int, n: int, pd: float, rho: float, volume: float, method: str
) -> None:
    means = data.draw(arrays((q, 2)))
    covs = data.draw(covariances(2, q)) if q else np.zeros((0, 2, 2))
    meas = data.draw(arrays((n, 2)))
    mcov = data.draw(covariances(2))

    def go() -> Any:
        d = asg.AssignmentData(means, covs, meas, mcov, volume, pd, rho)
        if method == "milp":
            return asg.solve(d)
        if method == "brute":
            return asg.brute_force(d)
        if method == "linear":
            return asg.linear_assignment(d)
        return asg.k_best(d, 2)

    accept(go)


test_assignment, test_assignment_slow = sweep(
    _assignment,
    data=st.data(),
    q=st.integers(0, 4),
    n=st.integers(0, 5),
    pd=st.sampled_from([0.9, 0.0, 1.0, 1.5, np.nan]),
    rho=st.sampled_from([0.05, 0.0, -1.0, np.inf]),
    volume=st.sampled_from([100.0, 0.0, -1.0, 1e300]),
    method=st.sampled_from(["milp", "brute", "linear", "kbest"]),
)


# ------------------------------------------------------------------------ montecarlo
def _montecarlo(trials: Any, seed: Any, scheduler: Any) -> None:
    sched = "serial" if scheduler is None else scheduler  # no process pool per example
    accept(lambda: mc.run(mc.TrajectoriesEta(q=2, n=3), trials, seed, scheduler=sched))


test_montecarlo, test_montecarlo_slow = sweep(
    _montecarlo,
    trials=st.one_of(st.integers(-2, 3), st.floats(allow_nan=True), st.none()),
    seed=st.one_of(st.integers(-3, 3), st.floats(allow_nan=True), st.text(max_size=2)),
    scheduler=st.sampled_from([None, "serial", "threads", "tcp:/x", 3]),
)
