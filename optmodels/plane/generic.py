r"""The generic solve of the plane problem in CasADi: the NLPs and the multistart solve.

``"full"``: the original problem (1.2)-(1.3) in all 3N + 4 unknowns; ``"reduced"``:
(1.12)-(1.13) in ``(n, a)``, valid for general :math:`D_i` (both written in
:mod:`optmodels.plane.formulations`). Both are built once per structure
(:func:`cached_nlp`, in the CasADi back-end's one cache of built NLPs, namespace
``"plane"``; the data enter as parameters) and solved by :func:`solve` from up to three
starts along the principal axes of the scaled data, every run re-checked by
:mod:`optmodels.plane.verify`. With IPOPT each start of the full NLP
goes in two phases (``via_reduced``): the reduced NLP from the axis to its local minimum
(4 unknowns), then the full NLP from that plane and its points (1.8); the full NLP's cost
per start is then one or two factorizations of its sparse KKT matrix, O(N), instead of
about 20 IPOPT iterations with inertia corrections from an axis that is a saddle or a
maximum of the profile (issue 19: N = 10⁴ with 3 starts 2.2 s → 0.37 s).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from optmodels.backends.casadi_backend import (
    NLP_CACHE,
    PRECISION_LIMIT,
    BuiltNlp,
    accept_precision_limit,
    cached_nlpsol,
    run_nlpsol,
)
from optmodels.core import (
    FloatArray,
    ProblemError,
    SolverNotAvailable,
    Status,
    as_choice,
    as_count,
    as_finite_array,
    as_flag,
    as_instance,
    timed,
)
from optmodels.plane.data import PlaneData, _oblique_projection, _weighted_offset
from optmodels.plane.formulations import _full_derivatives, _full_problem, _reduced_problem, _upper
from optmodels.plane.solution import PlaneSolution
from optmodels.plane.verify import _finish, _profile_check, _resolve

Formulation = Literal["full", "reduced"]


@dataclass(frozen=True)
class _Scaled:
    r"""Data moved to the unweighted centroid and scaled to unit RMS spread.

    Translation and scaling map planes to planes and leave (1.2) unchanged when the
    covariances are scaled with the points, so IPOPT sees well-scaled numbers whatever the
    units or the distance from the origin; the plane is mapped back exactly:
    :math:`\langle n, y\rangle = b` with :math:`y = (x - c)/s` is
    :math:`\langle n, x\rangle = s b + \langle n, c\rangle`.
    """

    center: FloatArray
    scale: float
    points: FloatArray  # (N, 3) scaled
    covs: FloatArray  # (N, 3, 3) scaled

    @classmethod
    def of(cls, data: PlaneData) -> _Scaled:
        c = data.points.mean(axis=0)
        y = data.points - c
        s = float(np.sqrt(np.mean(np.sum(y * y, axis=1))))
        return cls(center=c, scale=s, points=y / s, covs=data.covs / s**2)


#: IPOPT options of the full NLP (under the user's, unless they choose another
#: ``linear_solver``): MUMPS's QAMD ordering, which detects the quasi-dense rows n, a of
#: the KKT matrix. MUMPS's automatic choice spends O(N²) in its analysis on them (1.1 s per
#: start at N = 2·10⁴, against 0.03 s with QAMD). (CasADi's IPOPT always has MUMPS.)
FULL_IPOPT_DEFAULTS: dict[str, Any] = {"mumps_pivot_order": 6}


#: The built NLPs live in the CasADi back-end's one cache, under this namespace.
_CACHE_NAMESPACE = "plane"


def cached_nlp(
    formulation: Formulation, n: int, options: dict[str, Any] | None, plugin: str = "ipopt"
) -> tuple[BuiltNlp, bool]:
    """Built NLP for this structure, and whether it was built by this call.

    The symbolic construction does not depend on the data values, so Monte Carlo and
    sequential runs pay it once per (formulation, N, options).
    """
    full = formulation == "full"
    if full and plugin == "ipopt" and (options or {}).get("linear_solver", "mumps") == "mumps":
        options = {**FULL_IPOPT_DEFAULTS, **(options or {})}
    return cached_nlpsol(
        _CACHE_NAMESPACE,
        (formulation, n),
        lambda: _full_problem(n) if full else _reduced_problem(n),
        plugin=plugin,
        options=options,
        derivatives=(lambda: _full_derivatives(n)) if full and plugin == "ipopt" else None,
    )


#: A stationary point whose smallest profile curvature is below -1e-6 of the largest is a
#: saddle or a maximum of (1.12)-(1.13), not a solution (finite-difference accuracy of the
#: relative curvature is ~1e-8).
_SADDLE_RTOL = 1e-6


def clear_nlp_cache() -> None:
    """Forget the built CasADi NLPs (the next solve pays the construction again; used by
    benchmarks that measure cold build + solve)."""
    NLP_CACHE.clear(_CACHE_NAMESPACE)


def _reduced_start(
    built: BuiltNlp, params: FloatArray, sc: _Scaled, nv0: FloatArray
) -> tuple[FloatArray, float, float, int]:
    r"""Phase 1 of a start of the full NLP: the reduced NLP (1.12)-(1.13) from the start
    normal ``nv0`` (scaled data), to its local minimum.

    Returns the start plane for the full NLP (unit normal, offset in the scaled frame),
    the seconds and the IPOPT iterations spent. A run that fails (any status but OPTIMAL,
    OPTIMAL_INACCURATE or IPOPT's precision limit, or a non-finite point) gives back
    ``nv0`` and its weighted offset: the full NLP then starts from the axis itself, as
    with ``via_reduced=False``.
    """
    b0 = _weighted_offset(sc.points, sc.covs, nv0)[2]
    res, xopt = run_nlpsol(built, x0=np.concatenate([nv0, [b0]]), p=params)
    nv, b = xopt[:3], float(xopt[3])
    usable = (res.status.ok or res.message == PRECISION_LIMIT) and np.all(np.isfinite(xopt))
    norm = float(np.linalg.norm(nv)) if usable else 0.0
    if not norm > 0:
        return nv0, b0, res.solve_time, res.iterations or 0
    # the offset is the reduced solver's own; ‖n‖ = 1 holds to its tolerance
    return nv / norm, b / norm, res.solve_time, res.iterations or 0


def _principal_axes(points: FloatArray) -> FloatArray:
    """Rows: unit axes of the unweighted scatter, smallest variance first."""
    y = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(y.T @ y)
    return vecs.T


def solve(
    data: PlaneData,
    formulation: Formulation = "full",
    *,
    starts: int | Literal["auto"] = "auto",
    initial_normal: ArrayLike | None = None,
    ipopt_options: dict[str, Any] | None = None,
    plugin: str = "ipopt",
    plugin_options: dict[str, Any] | None = None,
    via_reduced: bool | None = None,
    level: float | None = 0.997,
) -> PlaneSolution:
    """Solve the ML plane problem generically with CasADi + IPOPT (or another NLP plugin).

    Parameters
    ----------
    data : PlaneData
    formulation : {"full", "reduced"}
        ``"full"``: the original problem (1.2)-(1.3) in all 3N + 4 unknowns.
        ``"reduced"``: (1.12)-(1.13) in (n, a), valid for general :math:`D_i`.
    starts : "auto" or int 1..3
        Starts along the principal axes of the *unweighted* scatter (smallest variance
        first); the best KKT point is kept. Never started from the closed form (the
        full NLP with IPOPT goes through the reduced NLP from the same axis first, see
        ``via_reduced``).
        ``"auto"`` (default): under (1.4), the first axis, then the other two only if it
        failed or fails the second-order check (``info["min_curvature"] <= 0``: not a
        local minimum of the profile :math:`\\Phi(n) = \\min_a \\varphi(a, n)` on the
        sphere); for general :math:`D_i` all three.
    initial_normal : array_like (3,), optional
        Start from this normal instead (a single start, e.g. a warm start in a sequence).
    ipopt_options : dict, optional
        Extra IPOPT options (defaults: ``tol = constr_viol_tol = 1e-10``).
    plugin : str
        CasADi ``nlpsol`` plugin: ``"ipopt"`` (default) or another that loads here, e.g.
        ``"sqpmethod"``, ``"blocksqp"``, ``"feasiblesqpmethod"`` (see
        :data:`optmodels.backends.casadi_backend.NLP_PLUGINS`). Every result is re-checked
        against (1.3) in NumPy whatever the plugin.
    plugin_options : dict, optional
        Options for a plugin other than IPOPT (CasADi's option dictionary).
    via_reduced : bool, optional
        ``"full"`` only: start the full NLP of each start from the local minimum that the
        reduced NLP (1.12)-(1.13) (IPOPT, the same ``ipopt_options``) reaches from the
        same start normal, the points :math:`x_i` by (1.8) on that plane (phase 1, a
        4-unknown NLP costing O(N) per iteration); then IPOPT solves (1.2)-(1.3) in all
        3N + 4 unknowns from there (phase 2), to its own KKT test. Default (None): True
        for ``plugin="ipopt"``, False for the other plugins (whose comparison is then
        not reduced to a check of IPOPT's point). False: the full NLP starts from the
        axis itself, an independent solve (about 20 IPOPT iterations from each of the
        axes that are a saddle or a maximum of the profile: 2.2 s at N = 10⁴ with 3
        starts, against 0.37 s). A phase 1 that fails hands the axis itself to phase 2.
    level : float or None
        Level of the line test behind ``resolved`` (default 0.997): a plane whose points
        are on a line at this level is returned unresolved (status ERROR, NaN normal,
        ``line_direction``; :func:`optmodels.plane.verify._resolve`). ``None``: no test.

    Returns
    -------
    PlaneSolution
        The best successful start. If no start succeeded, the status is not OK (and
        ``require_ok()`` raises). ``build_time`` is the CasADi construction when it
        happened in this call (``info["cached_build"]`` says whether it was reused);
        ``info["start_objectives"]`` lists each start's value of (1.2),
        ``info["start_iterations"]`` its IPOPT iterations on the chosen formulation.
        ``info["via_reduced"]`` says whether the full NLP's starts came from the reduced
        NLP; ``info["reduced_iterations"]`` / ``info["reduced_solve_time"]`` are phase
        1's (included in ``solve_time``; ``iterations`` counts phase 2, the full NLP's).

    Notes
    -----
    What is guaranteed: each successful run is a KKT point of the chosen formulation to
    IPOPT's tolerance, re-checked against (1.3) in ``residuals``. Under (1.4) every local
    minimum of the Rayleigh quotient (1.15) is global (its other stationary points, the
    other generalized eigenvectors, are a saddle and a maximum), so any run that reaches a
    local minimum is the global ML plane. A run that stops on a saddle or maximum (a start
    exactly on one, e.g. a principal axis when ``D`` is isotropic) is caught by the
    second-order check, and the remaining starts are tried. For general :math:`D_i`
    (1.12) can have spurious local minima (seen in tests: a strict local minimum with
    (1.2) four orders of magnitude above the global one), so all three starts are run;
    this is a heuristic, not a global guarantee -- compare ``info["start_objectives"]``.

    Every run ends in a NumPy re-check against (1.2)-(1.3) (``info["verification"]``):
    the residuals of (1.3), the Newton step of the profile :math:`\\Phi` on the sphere
    (analytic gradient, finite-difference Hessian; an estimate in rad of the normal's
    error, inf when the curvature does not clear its round-off floor, e.g. nearly collinear
    points) and, for ``"full"``, the distance of the solver's :math:`x_i` from (1.8) in
    noise standard deviations; then :func:`optmodels.core.verified_status`. A stationary
    point with negative curvature (saddle or maximum) is reported as ERROR.
    """
    formulation, auto, n_starts, via_reduced = _check_args(
        data, formulation, starts, plugin, ipopt_options, plugin_options, via_reduced
    )
    sc = _Scaled.of(data)
    if initial_normal is not None:
        n0 = as_finite_array("plane.solve initial_normal", initial_normal, shape=(3,))
        if not np.linalg.norm(n0) > 0:
            raise ProblemError("plane.solve initial_normal: must be non-zero")
        start_normals = [n0 / np.linalg.norm(n0)]
    else:
        start_normals = list(_principal_axes(sc.points)[:n_starts])
    built = _build(formulation, sc, plugin, ipopt_options, plugin_options, via_reduced)
    runs = _Runs()
    best: PlaneSolution | None = None
    first_fail: PlaneSolution | None = None
    curvature = float("nan")
    for nv0 in start_normals:
        if (
            auto
            and data.proportional
            and len(runs.objectives) == 1
            and best is not None
            and curvature > 0
        ):
            # Under (1.4) a local minimum of Φ on the sphere is the global one.
            break
        sol, curv_i = _run_start(data, sc, built, formulation, plugin, nv0, runs)
        if sol.ok and (best is None or sol.objective < best.objective):
            best = sol
            curvature = curv_i
        elif not sol.ok and first_fail is None:
            first_fail = sol
    out = best if best is not None else first_fail
    assert out is not None
    return _resolve(_package(out, built, runs, via_reduced), data, level)


def _check_args(
    data: PlaneData,
    formulation: Any,
    starts: Any,
    plugin: Any,
    ipopt_options: Any,
    plugin_options: Any,
    via_reduced: Any,
) -> tuple[Formulation, bool, int, bool]:
    """The arguments of :func:`solve` checked: the formulation, whether the starts are
    automatic, how many axes to start from, and whether the full NLP starts from the
    reduced one."""
    as_instance("plane.solve data", data, PlaneData)
    form: Formulation = as_choice(  # type: ignore[assignment]
        "plane.solve formulation", formulation, ("full", "reduced")
    )
    auto = isinstance(starts, str) and starts == "auto"
    n_starts = 3
    if not auto:
        if isinstance(starts, str):
            raise ProblemError(f"plane.solve starts: expected 'auto', 1, 2 or 3, got {starts!r}")
        n_starts = as_count("plane.solve starts", starts, minimum=1, maximum=3)
    if not isinstance(plugin, str) or not plugin:
        raise ProblemError(f"plane.solve plugin: expected a CasADi nlpsol name, got {plugin!r}")
    for name, opts in (("ipopt_options", ipopt_options), ("plugin_options", plugin_options)):
        if opts is not None and (
            not isinstance(opts, dict) or not all(isinstance(k, str) for k in opts)
        ):
            raise ProblemError(
                f"plane.solve {name}: expected a dict with str keys or None, "
                f"got {type(opts).__name__}"
            )
    reduced_first = as_flag(
        "plane.solve via_reduced", via_reduced if via_reduced is not None else plugin == "ipopt"
    )
    return form, auto, n_starts, reduced_first and form == "full"


@dataclass
class _Built:
    """The NLP(s) of one :func:`solve` and their parameter vectors."""

    nlp: Any
    params: FloatArray
    fresh: bool
    build_time: float
    reduced: Any = None
    reduced_params: FloatArray | None = None


def _build(
    formulation: Formulation,
    sc: _Scaled,
    plugin: str,
    ipopt_options: dict[str, Any] | None,
    plugin_options: dict[str, Any] | None,
    via_reduced: bool,
) -> _Built:
    """The NLP from the back-end's cache (built when new) and its parameters (the scaled
    points and the covariances, or their inverses for ``"full"``)."""
    n_pts = len(sc.points)
    red_built, red_params = None, None
    with timed() as t_prep:
        try:
            if plugin == "ipopt":
                built, fresh = cached_nlp(formulation, n_pts, ipopt_options)
            else:
                built, fresh = cached_nlp(formulation, n_pts, plugin_options, plugin)
        except RuntimeError as exc:  # CasADi: unknown plugin/option, missing library
            raise SolverNotAvailable(
                f"plugin: CasADi nlpsol {plugin!r} could not be built for the plane NLP: "
                f"{str(exc).splitlines()[0][:200]}"
            ) from exc
        pts_param = sc.points.T.ravel(order="F")
        if formulation == "full":
            params = np.concatenate(
                [
                    pts_param,
                    _upper(np.asarray(np.linalg.inv(sc.covs), dtype=float)).ravel(order="F"),
                ]
            )
        else:
            params = np.concatenate([pts_param, _upper(sc.covs).ravel(order="F")])
        if via_reduced:
            red_built, red_fresh = cached_nlp("reduced", n_pts, ipopt_options)
            fresh = fresh or red_fresh
            red_params = np.concatenate([pts_param, _upper(sc.covs).ravel(order="F")])
    # build_time includes the construction when it happened here
    return _Built(
        nlp=built,
        params=params,
        fresh=fresh,
        build_time=t_prep.elapsed,
        reduced=red_built,
        reduced_params=red_params,
    )


@dataclass
class _Runs:
    """What every start of :func:`solve` reported (its ``info``)."""

    objectives: list[float] = field(default_factory=list)
    status: list[str] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    solve_time: float = 0.0
    total_iterations: int = 0
    reduced_time: float = 0.0
    reduced_iterations: int = 0


def _run_start(
    data: PlaneData,
    sc: _Scaled,
    built: _Built,
    formulation: Formulation,
    plugin: str,
    nv0: FloatArray,
    runs: _Runs,
) -> tuple[PlaneSolution, float]:
    """One start of :func:`solve` from the normal ``nv0``, re-checked and gated
    (:func:`optmodels.plane.verify._finish`); returns the solution and its profile
    curvature, and records the run in ``runs``."""
    n_pts = data.n_points
    # Start plane (nv0, b0): b0 and the x_i are the best ones *for that plane* --
    # the weighted offset and the oblique projections (1.8), not orthogonal ones,
    # which under anisotropic D_i start far from optimal and cost IPOPT dozens of
    # iterations. This uses only the start plane (the axis, or with via_reduced the
    # reduced NLP's local minimum from the axis), never the closed-form solution.
    if built.reduced is not None:
        assert built.reduced_params is not None
        nv0, b0, t_red, it_red = _reduced_start(built.reduced, built.reduced_params, sc, nv0)
        runs.reduced_time += t_red
        runs.reduced_iterations += it_red
    else:
        b0 = _weighted_offset(sc.points, sc.covs, nv0)[2]
    if formulation == "full":
        x_start = _oblique_projection(sc.points, sc.covs, nv0, b0)
        x0 = np.concatenate([x_start.T.ravel(order="F"), nv0, [b0]])
    else:
        x0 = np.concatenate([nv0, [b0]])
    res, xopt = run_nlpsol(built.nlp, x0=x0, p=built.params)
    runs.solve_time += res.solve_time
    runs.total_iterations += res.iterations or 0
    runs.iterations.append(res.iterations or 0)
    k = 3 * n_pts if formulation == "full" else 0
    normal, b = xopt[k : k + 3], float(xopt[k + 3])
    # The solver's own normal (not renormalised), so that a violated ‖n‖ = 1 shows in
    # the residuals; "full" reports its own x_i, "reduced" projects by (1.8).
    offset = b * sc.scale + float(normal @ sc.center)
    x_scaled = xopt[:k].reshape(n_pts, 3) if formulation == "full" else None
    proj = None
    if x_scaled is not None and np.all(np.isfinite(xopt)):
        proj = x_scaled * sc.scale + sc.center
    status = res.status
    message = res.message
    curv_i, step_i = float("nan"), float("inf")
    if np.all(np.isfinite(normal)) and np.linalg.norm(normal) > 0:
        chk = _profile_check(sc.points, sc.covs, normal / np.linalg.norm(normal))
        curv_i, step_i = float(chk.curvature[0]), float(chk.step[0])
        # IPOPT's precision limit: accept only a point verified independently
        # (the re-check in _finish then applies to it like to any other).
        status, message = accept_precision_limit(
            status,
            message,
            step_i,
            f" (KKT point verified: Newton step {step_i:.1e} rad, curvature {curv_i:.2f})",
        )
        if status.ok and curv_i < -_SADDLE_RTOL:
            status = Status.ERROR
            message += (
                f"; not a minimum of (1.12)-(1.13): profile curvature {curv_i:.2g}"
                " (a saddle or maximum)"
            )
    sol = _finish(
        data,
        normal,
        offset,
        status=status,
        method=f"casadi:{plugin}:{formulation}",
        stationarity=step_i,
        message=message,
        projected=proj,
        info={"min_curvature": curv_i},
    )
    runs.objectives.append(sol.objective)
    runs.status.append(res.message)
    return sol, curv_i


def _package(out: PlaneSolution, built: _Built, runs: _Runs, via_reduced: bool) -> PlaneSolution:
    """The chosen start's solution with the times and the ``info`` of every start."""
    verification = out.info.get("verification", {})
    curvature = float(out.info.get("min_curvature", float("nan")))
    out.build_time = built.build_time
    out.solve_time = runs.solve_time + runs.reduced_time
    out.iterations = runs.total_iterations
    out.info = {
        "start_objectives": runs.objectives,
        "start_status": runs.status,
        "start_iterations": runs.iterations,
        "starts": len(runs.objectives),
        "min_curvature": curvature,
        "cached_build": not built.fresh,
        "via_reduced": via_reduced,
        "reduced_iterations": runs.reduced_iterations,
        "reduced_solve_time": runs.reduced_time,
        "verification": verification,
        **({"rejected": out.info["rejected"]} if "rejected" in out.info else {}),
    }
    return out
