"""CasADi back-end: run a built ``nlpsol`` function and report status, timings, iterations.

Problem modules build their NLP once per structure (data enter as parameters ``p``) in
the one cache :data:`NLP_CACHE` (:func:`cached_nlpsol`, keyed by problem namespace and
structure, FIFO-bounded per namespace), so that Monte Carlo and sequential runs pay the
symbolic construction only once; :func:`build_nlpsol` times that construction and
:func:`run_nlpsol` one solve. :func:`accept_precision_limit` is the one rule for IPOPT's
precision limit (accepted as OPTIMAL_INACCURATE only after the problem's NumPy check).
Status tables: :data:`IPOPT_STATUS` covers every IPOPT ``ApplicationReturnStatus``,
:data:`SQP_STATUS` every ``return_status`` of CasADi's sqpmethod and feasiblesqpmethod, and
:data:`UNIFIED_STATUS` CasADi's plugin-independent ``unified_return_status`` (used for
every other plugin: fatrop, blocksqp, ...). An unknown string maps to ``Status.ERROR``, and
no plugin's result is OPTIMAL unless CasADi's own ``success`` flag is set.

Options are checked when the solver is built: an unknown option, a value of the wrong type
or a value the plugin rejects (IPOPT checks values at its first call: a probe solve of a
one-variable NLP finds those) raises :class:`~optmodels.core.ProblemError` naming the
option, never a raw CasADi ``RuntimeError``. An unknown plugin name raises
:class:`~optmodels.core.SolverNotAvailable`.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from optmodels.backends.common import BackendResult, last_line, probe_in_child, quiet_fds
from optmodels.core import VERIFY_TOL, ProblemError, SolverNotAvailable, Status

__all__ = [
    "IPOPT_STATUS",
    "NLP_CACHE",
    "NLP_PLUGINS",
    "NLP_PLUGIN_DEFAULTS",
    "SQP_STATUS",
    "UNIFIED_STATUS",
    "BuiltNlp",
    "NlpCache",
    "accept_precision_limit",
    "build_nlpsol",
    "cached_nlpsol",
    "check_options",
    "nlp_plugins",
    "nlp_status",
    "probe_nlp_plugins",
    "run_nlpsol",
]

#: CasADi NLP plugins the comparison tries, in report order (commercial ones left out).
NLP_PLUGINS = ("ipopt", "sqpmethod", "feasiblesqpmethod", "blocksqp", "fatrop")
_QRQP_QUIET = {
    "print_iter": False,
    "print_header": False,
    "print_info": False,
    "error_on_fail": False,
}
#: Quiet defaults per plugin; sqpmethod and feasiblesqpmethod use CasADi's own qrqp QP
#: solver (no third-party library involved).
NLP_PLUGIN_DEFAULTS: dict[str, dict[str, Any]] = {
    "sqpmethod": {
        "qpsol": "qrqp",
        "qpsol_options": _QRQP_QUIET,
        "print_header": False,
        "print_iteration": False,
        "print_status": False,
        "max_iter": 200,
        "error_on_fail": False,
    },
    "feasiblesqpmethod": {
        "qpsol": "qrqp",
        "qpsol_options": _QRQP_QUIET,
        "print_header": False,
        "print_iteration": False,
        "print_status": False,
        "max_iter": 200,
        "error_on_fail": False,
    },
    "blocksqp": {
        "print_header": False,
        "print_iteration": False,
        "print_maxit_reached": False,
        "error_on_fail": False,
    },
    "fatrop": {"fatrop": {"print_level": 0}, "error_on_fail": False},
}


_NLP_PROBE = r"""
import sys
import casadi as ca
import numpy as np
from optmodels.backends.casadi_backend import build_nlpsol
for plugin in sys.argv[1:]:
    if not ca.has_nlpsol(plugin):
        print(plugin, "does not load", flush=True); continue
    x = ca.SX.sym("x", 2)
    try:
        built = build_nlpsol({"x": x, "f": ca.sumsqr(x), "g": x[0] + x[1] - 1}, plugin=plugin)
        res = built.solver(x0=[1.0, 0.0], lbg=0, ubg=0)  # a feasible start
        xs = np.asarray(res["x"], dtype=float).ravel()
        ok = bool(built.solver.stats().get("success")) and np.allclose(xs, 0.5, atol=1e-6)
        print(plugin, "ok" if ok else "wrong answer on the test NLP", flush=True)
    except RuntimeError as exc:
        lines = [ln for ln in str(exc).splitlines() if "Error code" in ln]
        msg = (lines[0].strip() if lines else str(exc).splitlines()[0])[:160]
        print(plugin, "error: " + msg, flush=True)
"""


@functools.cache
def probe_nlp_plugins() -> dict[str, str]:
    """For each of :data:`NLP_PLUGINS`: ``"ok"`` if it loads and solves
    ``min ‖x‖² s.t. x₁ + x₂ = 1`` to 1e-6, else why not (e.g. blocksqp needs HSL's MA27,
    which is not redistributed with CasADi). Runs in a child interpreter (see
    :func:`optmodels.backends.common.probe_in_child`)."""
    return probe_in_child(_NLP_PROBE, NLP_PLUGINS)


def nlp_plugins() -> tuple[str, ...]:
    """The plugins of :data:`NLP_PLUGINS` that load and pass :func:`probe_nlp_plugins`."""
    return tuple(p for p, v in probe_nlp_plugins().items() if v == "ok")


IPOPT_STATUS: dict[str, Status] = {
    "Solve_Succeeded": Status.OPTIMAL,
    "Solved_To_Acceptable_Level": Status.OPTIMAL_INACCURATE,
    "Feasible_Point_Found": Status.OPTIMAL_INACCURATE,
    "Infeasible_Problem_Detected": Status.INFEASIBLE,
    "Search_Direction_Becomes_Too_Small": Status.ERROR,
    "Diverging_Iterates": Status.UNBOUNDED,
    "User_Requested_Stop": Status.ERROR,
    "Maximum_Iterations_Exceeded": Status.ITERATION_LIMIT,
    "Maximum_CpuTime_Exceeded": Status.ITERATION_LIMIT,
    "Maximum_WallTime_Exceeded": Status.ITERATION_LIMIT,
    "Restoration_Failed": Status.ERROR,
    "Error_In_Step_Computation": Status.ERROR,
    "Not_Enough_Degrees_Of_Freedom": Status.ERROR,
    "Invalid_Problem_Definition": Status.ERROR,
    "Invalid_Option": Status.ERROR,
    "Invalid_Number_Detected": Status.ERROR,
    "Unrecoverable_Exception": Status.ERROR,
    "NonIpopt_Exception_Thrown": Status.ERROR,
    "Insufficient_Memory": Status.ERROR,
    "Internal_Error": Status.ERROR,
}

#: ``return_status`` of CasADi's sqpmethod and feasiblesqpmethod (every string in their
#: 3.8 sources). Their precision limit, Search_Direction_Becomes_Too_Small, is an ERROR
#: here as for IPOPT; a problem module may accept the point after its own NumPy check.
SQP_STATUS: dict[str, Status] = {
    "Solve_Succeeded": Status.OPTIMAL,
    "Maximum_Iterations_Exceeded": Status.ITERATION_LIMIT,
    "Search_Direction_Becomes_Too_Small": Status.ERROR,
    "Trust_Region_Radius_Becomes_Too_Small": Status.ERROR,
    "Non_Regular_Sensitivities": Status.ERROR,
    "No_Feasible_Initialization": Status.ERROR,
    "User_Requested_Stop": Status.ERROR,
}

#: CasADi's plugin-independent ``unified_return_status`` (``casadi_types.hpp``).
UNIFIED_STATUS: dict[str, Status] = {
    "SOLVER_RET_SUCCESS": Status.OPTIMAL,
    "SOLVER_RET_LIMITED": Status.ITERATION_LIMIT,
    "SOLVER_RET_INFEASIBLE": Status.INFEASIBLE,
    "SOLVER_RET_NAN": Status.ERROR,
    "SOLVER_RET_EXCEPTION": Status.ERROR,
    "SOLVER_RET_UNKNOWN": Status.ERROR,
}

_PLUGIN_STATUS: dict[str, dict[str, Status]] = {
    "ipopt": IPOPT_STATUS,
    "sqpmethod": SQP_STATUS,
    "feasiblesqpmethod": SQP_STATUS,
}


def nlp_status(plugin: str, stats: dict[str, Any]) -> Status:
    """:class:`Status` of a finished ``nlpsol`` call from its ``stats()``.

    The plugin's own table (:data:`IPOPT_STATUS`, :data:`SQP_STATUS`) decides for the
    strings it lists; any other plugin, or a string its table lacks, goes through
    :data:`UNIFIED_STATUS`; anything still unknown is ERROR. OPTIMAL additionally needs
    CasADi's ``success`` flag (a table entry never overrides a reported failure).
    """
    code = str(stats.get("return_status", "unknown"))
    table = _PLUGIN_STATUS.get(plugin, {})
    if code in table:
        status = table[code]
    else:
        status = UNIFIED_STATUS.get(str(stats.get("unified_return_status", "")), Status.ERROR)
    if status == Status.OPTIMAL and not stats.get("success", False):
        return Status.ERROR
    return status


#: IPOPT defaults used by optmodels: quiet, and tight enough that the original-form
#: residuals come out at round-off level on problems scaled to O(1). (1e-12 was tried:
#: IPOPT then often ends at its precision limit, Search_Direction_Becomes_Too_Small.)
IPOPT_DEFAULTS: dict[str, Any] = {
    "print_level": 0,
    "sb": "yes",
    "tol": 1e-10,
    "constr_viol_tol": 1e-10,
    "max_iter": 500,
}


@dataclass
class BuiltNlp:
    """A built ``nlpsol`` function, the seconds its construction took, and its plugin."""

    solver: ca.Function
    build_time: float
    plugin: str


def build_nlpsol(
    nlp: dict[str, Any],
    *,
    plugin: str = "ipopt",
    options: dict[str, Any] | None = None,
    derivatives: dict[str, ca.Function] | None = None,
) -> BuiltNlp:
    """Build ``ca.nlpsol`` for ``nlp`` (keys x, f, g, p) with quiet defaults.

    ``options`` go to IPOPT itself for ``plugin="ipopt"`` (merged over
    :data:`IPOPT_DEFAULTS`), to CasADi's plugin options otherwise (over
    :data:`NLP_PLUGIN_DEFAULTS`). ``derivatives``: CasADi functions the problem writes
    itself instead of the ones CasADi generates (plugin options ``jac_g``: ``(x, p) ->
    (g, jac_g_x)``, ``hess_lag``: ``(x, p, lam_f, lam_g) -> (triu_hess_gamma_x_x)``,
    ``grad_f``: ``(x, p) -> (f, grad_f_x)``), e.g. when CasADi's sparsity detection and
    colouring of a Jacobian with dense columns costs O(N²) (the plane's full NLP).

    Raises
    ------
    SolverNotAvailable
        ``plugin`` is not a CasADi NLP plugin that loads here.
    ProblemError
        ``options`` is not a dictionary with string keys, or an option is unknown to the
        plugin, has the wrong type or a value the plugin rejects; the message names the
        option and quotes CasADi/IPOPT.
    """
    plugin = _check_plugin(plugin)
    user = check_options(options)
    opts = {**_plugin_options(plugin, user), **(derivatives or {})}
    t0 = time.perf_counter()
    try:
        with quiet_fds():  # a refused option is in the exception; IPOPT also prints it
            solver = ca.nlpsol("optmodels_nlp", plugin, nlp, opts)
    except RuntimeError as exc:
        raise _option_error(plugin, user, exc) from None
    build_time = time.perf_counter() - t0
    if plugin == "ipopt" and user:
        # IPOPT checks option values only when it is first called: a probe solve
        # (one-variable NLP, about a millisecond) finds a rejected value now.
        bad = _probe_options(plugin, user)
        if bad is not None:
            raise _option_error(plugin, user, RuntimeError(bad))
    return BuiltNlp(solver=solver, build_time=build_time, plugin=plugin)


class NlpCache:
    """The one cache of built NLPs: keys are ``(namespace, *structure)`` (the data enter as
    parameters, so one build serves every solve of that structure), first in first out,
    at most ``size`` entries per namespace. ``clear(namespace)`` forgets one problem's
    builds (``plane.clear_nlp_cache``, ``fusion.clear_joint_cache``), ``clear()`` all."""

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self._built: dict[tuple[Any, ...], BuiltNlp] = {}

    def get(self, key: tuple[Any, ...], make: Callable[[], BuiltNlp]) -> tuple[BuiltNlp, bool]:
        """The NLP built for ``key``, and whether this call built it (with ``make``)."""
        if key in self._built:
            return self._built[key], False
        built = make()
        same = [k for k in self._built if k[0] == key[0]]
        if len(same) >= self.size:
            del self._built[same[0]]
        self._built[key] = built
        return built, True

    def clear(self, namespace: str | None = None) -> None:
        for k in [k for k in self._built if namespace is None or k[0] == namespace]:
            del self._built[k]

    def keys(self, namespace: str | None = None) -> list[tuple[Any, ...]]:
        return [k for k in self._built if namespace is None or k[0] == namespace]

    def __contains__(self, key: object) -> bool:
        return key in self._built

    def __len__(self) -> int:
        return len(self._built)


#: Built NLPs of every problem (see :class:`NlpCache`).
NLP_CACHE = NlpCache()


def cached_nlpsol(
    namespace: str,
    key: tuple[Any, ...],
    make_nlp: Callable[[], dict[str, Any]],
    *,
    plugin: str = "ipopt",
    options: dict[str, Any] | None = None,
    derivatives: Callable[[], dict[str, ca.Function]] | None = None,
) -> tuple[BuiltNlp, bool]:
    """:func:`build_nlpsol` of ``make_nlp()`` once per (``namespace``, ``key``, plugin,
    options) in :data:`NLP_CACHE`; returns the built NLP and whether this call built it.
    ``derivatives()`` (called only when building) gives :func:`build_nlpsol`'s
    ``derivatives``; they must be determined by ``key`` and ``plugin``."""
    full = (namespace, *key, plugin, repr(sorted((options or {}).items())))
    return NLP_CACHE.get(
        full,
        lambda: build_nlpsol(
            make_nlp(),
            plugin=plugin,
            options=options,
            derivatives=derivatives() if derivatives is not None else None,
        ),
    )


#: IPOPT's (and the SQP methods') return status at their precision limit.
PRECISION_LIMIT = "Search_Direction_Becomes_Too_Small"


def accept_precision_limit(
    status: Status, message: str, verified: float, note: str, tol: float = VERIFY_TOL
) -> tuple[Status, str]:
    """IPOPT stopped at its precision limit (:data:`PRECISION_LIMIT`, an ERROR in the
    tables): the point is accepted as OPTIMAL_INACCURATE only if the problem's own NumPy
    check ``verified`` (e.g. the Newton step to the stationary point) is at most ``tol``
    (:data:`optmodels.core.VERIFY_TOL`); ``note`` is appended to the message then. Any
    other status passes unchanged. The verification gate still applies afterwards."""
    if message == PRECISION_LIMIT and verified <= tol:
        return Status.OPTIMAL_INACCURATE, message + note
    return status, message


def _check_plugin(plugin: Any) -> str:
    if not isinstance(plugin, str):
        raise ProblemError(f"plugin: expected a CasADi NLP plugin name (str), got {plugin!r}")
    if not ca.has_nlpsol(plugin):
        raise SolverNotAvailable(
            f"plugin: CasADi NLP plugin {plugin!r} does not load here "
            f"(plugins tried by optmodels: {', '.join(NLP_PLUGINS)})"
        )
    return plugin


def check_options(options: Any) -> dict[str, Any]:
    """``options`` as a dict with string keys (None → {}); ProblemError otherwise."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ProblemError(
            f"options: expected a dict of solver options, got {type(options).__name__}"
        )
    bad = [k for k in options if not isinstance(k, str)]
    if bad:
        raise ProblemError(f"options: option names must be strings, got {bad[0]!r}")
    return dict(options)


def _plugin_options(plugin: str, user: dict[str, Any]) -> dict[str, Any]:
    opts: dict[str, Any] = {"print_time": False}
    if plugin == "ipopt":
        opts["ipopt"] = {**IPOPT_DEFAULTS, **user}
    else:
        opts.update(NLP_PLUGIN_DEFAULTS.get(plugin, {}))
        opts.update(user)
    return opts


def _probe_options(plugin: str, user: dict[str, Any]) -> str | None:
    """Build and (for IPOPT) run min x² with ``user`` options; the CasADi/IPOPT complaint,
    or None if the options are accepted."""
    x = ca.SX.sym("x")
    probe = {"x": x, "f": x * x, "g": x}
    code = None
    try:
        with quiet_fds():
            solver = ca.nlpsol("optmodels_probe", plugin, probe, _plugin_options(plugin, user))
            if plugin == "ipopt":
                solver(x0=1.0, lbg=-10.0, ubg=10.0)
                code = solver.stats().get("return_status")
            del solver  # IPOPT may print while the solver is destroyed: still silenced
            if plugin == "ipopt" and code == "Invalid_Option":
                return "IPOPT returned Invalid_Option"
    except RuntimeError as exc:
        return str(exc)
    return None


def _option_error(plugin: str, user: dict[str, Any], exc: RuntimeError) -> ProblemError:
    """Find the option CasADi refused (each alone in a probe build) and name it."""
    for key, value in user.items():
        why = _probe_options(plugin, {key: value})
        if why is not None:
            return ProblemError(
                f"options[{key!r}] = {value!r}: rejected by the CasADi "
                f"{plugin} plugin ({last_line(why)})"
            )
    what = f"options {user!r}" if user else "its defaults"
    return ProblemError(
        f"CasADi {plugin} plugin could not be built with {what} ({last_line(str(exc))})"
    )


def run_nlpsol(
    built: BuiltNlp,
    *,
    x0: np.ndarray,
    p: np.ndarray,
    lbg: Any = 0.0,
    ubg: Any = 0.0,
    lbx: Any = -np.inf,
    ubx: Any = np.inf,
) -> tuple[BackendResult, np.ndarray]:
    """Solve once from ``x0`` with parameters ``p``.

    Returns the common result fields and the primal point. The primal point is returned
    whatever the status (for diagnosis); callers must not report it as a solution unless
    ``result.status.ok``.
    """
    t0 = time.perf_counter()
    try:
        out = built.solver(x0=x0, p=p, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx)
    except RuntimeError as exc:  # CasADi raises on evaluation errors (NaN in callbacks)
        wall = time.perf_counter() - t0
        return (
            BackendResult(
                status=Status.ERROR,
                method=f"casadi:{built.plugin}",
                build_time=built.build_time,
                solve_time=wall,
                iterations=None,
                message=f"casadi error: {exc}",
            ),
            np.full(np.size(x0), np.nan),
        )
    wall = time.perf_counter() - t0
    stats = built.solver.stats()
    code = str(stats.get("return_status", "unknown"))
    status = nlp_status(built.plugin, stats)
    iters = stats.get("iter_count")
    x = np.asarray(out["x"], dtype=float).ravel()
    return (
        BackendResult(
            status=status,
            method=f"casadi:{built.plugin}",
            build_time=built.build_time,
            solve_time=wall,
            iterations=int(iters) if iters is not None else None,
            message=code,
            objective=float(out["f"]),
        ),
        x,
    )
