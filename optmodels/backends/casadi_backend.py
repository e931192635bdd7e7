"""CasADi back-end: run a built ``nlpsol`` function and report status, timings, iterations.

Problem modules build their NLP once per structure (data enter as parameters ``p``) and
cache it, so that Monte Carlo and sequential runs pay the symbolic construction only once;
:func:`build_nlpsol` times that construction and :func:`run_nlpsol` one solve.
The status table :data:`IPOPT_STATUS` covers every IPOPT ``ApplicationReturnStatus``;
an unknown string maps to ``Status.ERROR``.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from optmodels.backends.common import BackendResult, probe_in_child
from optmodels.core import Status

__all__ = ["IPOPT_STATUS", "NLP_PLUGINS", "NLP_PLUGIN_DEFAULTS", "BuiltNlp", "build_nlpsol",
           "nlp_plugins", "probe_nlp_plugins", "run_nlpsol"]

#: CasADi NLP plugins the comparison tries, in report order (commercial ones left out).
NLP_PLUGINS = ("ipopt", "sqpmethod", "feasiblesqpmethod", "blocksqp", "fatrop")
_QRQP_QUIET = {"print_iter": False, "print_header": False, "print_info": False,
               "error_on_fail": False}
#: Quiet defaults per plugin; sqpmethod and feasiblesqpmethod use CasADi's own qrqp QP
#: solver (no third-party library involved).
NLP_PLUGIN_DEFAULTS: dict[str, dict[str, Any]] = {
    "sqpmethod": {"qpsol": "qrqp", "qpsol_options": _QRQP_QUIET, "print_header": False,
                  "print_iteration": False, "print_status": False, "max_iter": 200,
                  "error_on_fail": False},
    "feasiblesqpmethod": {"qpsol": "qrqp", "qpsol_options": _QRQP_QUIET,
                          "print_header": False, "print_iteration": False,
                          "print_status": False, "max_iter": 200, "error_on_fail": False},
    "blocksqp": {"print_header": False, "print_iteration": False, "print_maxit_reached":
                 False, "error_on_fail": False},
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
    nlp: dict[str, Any], *, plugin: str = "ipopt", options: dict[str, Any] | None = None
) -> BuiltNlp:
    """Build ``ca.nlpsol`` for ``nlp`` (keys x, f, g, p) with quiet IPOPT defaults."""
    opts: dict[str, Any] = {"print_time": False}
    if plugin == "ipopt":
        opts["ipopt"] = {**IPOPT_DEFAULTS, **(options or {})}
    else:
        opts.update(NLP_PLUGIN_DEFAULTS.get(plugin, {}))
        opts.update(options or {})
    t0 = time.perf_counter()
    solver = ca.nlpsol("optmodels_nlp", plugin, nlp, opts)
    return BuiltNlp(solver=solver, build_time=time.perf_counter() - t0, plugin=plugin)


def run_nlpsol(
    built: BuiltNlp, *, x0: np.ndarray, p: np.ndarray, lbg: Any = 0.0, ubg: Any = 0.0,
    lbx: Any = -np.inf, ubx: Any = np.inf,
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
    status = IPOPT_STATUS.get(code, Status.ERROR) if built.plugin == "ipopt" else (
        Status.OPTIMAL if stats.get("success", False) else Status.ERROR
    )
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
