"""CasADi QP plugins (``casadi.conic``) as CVXPY solvers.

CVXPY canonicalises a problem to the QP form

.. math:: \\min \\tfrac12 x^T P x + q^T x \\quad\\text{s.t.}\\quad Ax = b,\\; Fx \\le g,

and hands the matrices to a :class:`cvxpy.reductions.solvers.qp_solvers.qp_solver.QpSolver`.
:class:`CasadiConic` is such a solver: it passes them to a CasADi ``conic`` plugin (osqp,
qpoases, highs, qrqp, proxqp, daqp, hpipm, superscs, ...) so that one model in CVXPY -- the
paper's original problem -- can be solved by CVXPY's own interfaces *and* by CasADi's,
and the two compared on identical data. Solver names are ``CASADI_<PLUGIN>`` (upper case);
:func:`casadi_qp_plugins` lists the plugins that load and solve a 2-variable test QP here.
"""

from __future__ import annotations

import functools
import time
from typing import Any

import casadi as ca
import cvxpy.settings as s
import numpy as np
import scipy.sparse as sp
from cvxpy.error import SolverError
from cvxpy.reductions.solution import Solution, failure_solution
from cvxpy.reductions.solvers import utilities
from cvxpy.reductions.solvers.qp_solvers.qp_solver import QpSolver

from optmodels.backends.common import last_line, probe_in_child
from optmodels.core import ProblemError

__all__ = [
    "CANDIDATE_PLUGINS",
    "CONIC_STATUS",
    "EXCLUDED",
    "PREFIX",
    "CasadiConic",
    "casadi_qp_plugins",
    "plugin_of",
    "probe_plugins",
]

PREFIX = "CASADI_"
#: CasADi conic plugins tried, in report order (commercial ones are left out: they need a
#: licence and their libraries, and CasADi prints a warning for each that does not load).
CANDIDATE_PLUGINS = ("osqp", "qpoases", "highs", "qrqp", "proxqp", "daqp", "hpipm", "superscs")
#: Quiet options per plugin (each plugin rejects options it does not know).
_QUIET: dict[str, dict[str, Any]] = {
    "osqp": {"osqp": {"verbose": False}},
    "qpoases": {"printLevel": "none"},
    "highs": {"highs": {"output_flag": False}},
    "qrqp": {"print_iter": False, "print_header": False, "print_info": False},
    "proxqp": {},
    "daqp": {},
    "hpipm": {},
    "superscs": {"superscs": {"verbose": 0}},
}


def plugin_of(name: str) -> str | None:
    """``"CASADI_OSQP"`` → ``"osqp"``; None for a name without the prefix."""
    up = name.upper()
    return up[len(PREFIX) :].lower() if up.startswith(PREFIX) else None


def _csc_to_dm(m: sp.sparray | sp.spmatrix) -> ca.DM:
    c = sp.csc_matrix(m)
    c.sort_indices()
    sparsity = ca.Sparsity(c.shape[0], c.shape[1], c.indptr.tolist(), c.indices.tolist())
    return ca.DM(sparsity, c.data.astype(float))


def _solve_qp(
    plugin: str,
    p: Any,
    q: np.ndarray,
    a: Any,
    lba: np.ndarray,
    uba: np.ndarray,
    options: dict[str, Any],
) -> tuple[dict[str, Any], dict[str, Any], float]:
    """Build and call ``casadi.conic``; returns outputs, stats and the call's seconds."""
    n = q.size
    h = _csc_to_dm(sp.csc_matrix(p) if p is not None else sp.csc_matrix((n, n)))
    # CasADi wants the full symmetric Hessian; CVXPY's P is symmetric already.
    am = _csc_to_dm(a)
    opts = {**_QUIET.get(plugin, {}), "error_on_fail": False, **options}
    sparsity = {"h": h.sparsity(), "a": am.sparsity()}
    try:
        solver = ca.conic("optmodels_qp", plugin, sparsity, opts)
    except RuntimeError as exc:
        raise _option_error(plugin, options, sparsity, exc) from None
    t0 = time.perf_counter()
    try:
        out = solver(h=h, g=q, a=am, lba=lba, uba=uba)
    except RuntimeError as exc:  # evaluation failure inside the plugin: a solver failure
        raise SolverError(f"CasADi conic plugin {plugin}: {last_line(str(exc))}") from None
    wall = time.perf_counter() - t0
    return out, solver.stats(), wall


def _option_error(
    plugin: str, options: dict[str, Any], sparsity: dict[str, Any], exc: RuntimeError
) -> ProblemError:
    """Name the option ``ca.conic`` refused (each user option alone in a probe build)."""
    for key, value in options.items():
        try:
            ca.conic(
                "optmodels_probe",
                plugin,
                sparsity,
                {**_QUIET.get(plugin, {}), "error_on_fail": False, key: value},
            )
        except RuntimeError as one:
            return ProblemError(
                f"solver option {key!r} = {value!r}: rejected by the CasADi "
                f"conic plugin {plugin} ({last_line(str(one))})"
            )
    return ProblemError(
        f"CasADi conic plugin {plugin} could not be built with options "
        f"{options!r} ({last_line(str(exc))})"
    )


class CasadiConic(QpSolver):  # type: ignore[misc]  # (CVXPY is not analysed)
    """A CVXPY QP solver that calls the CasADi ``conic`` plugin ``plugin``.

    Parameters
    ----------
    plugin : str
        CasADi conic plugin name (``osqp``, ``qpoases``, ``highs``, ``qrqp``, ...).

    Notes
    -----
    Solver options passed to ``problem.solve(solver=CasadiConic(...), **opts)`` go to the
    plugin unchanged (CasADi's own option dictionary); one the plugin refuses raises
    :class:`~optmodels.core.ProblemError` naming it. The status is CasADi's ``success``
    flag: OPTIMAL when set; otherwise :data:`CONIC_STATUS` of the unified return status
    (infeasible, or SOLVER_ERROR), SOLVER_ERROR for a code it lacks. Callers re-check the
    solution against the original problem in NumPy anyway.
    """

    MIP_CAPABLE = False

    def __init__(self, plugin: str) -> None:
        self.plugin = plugin.lower()

    def name(self) -> str:
        return PREFIX + self.plugin.upper()

    def cite(self, data: Any) -> str:
        return "CasADi (Andersson et al., Math. Prog. Comp. 11, 2019), conic plugin " + self.plugin

    def import_solver(self) -> None:
        if self.plugin in EXCLUDED:
            raise ImportError(f"CasADi conic plugin {self.plugin!r}: {EXCLUDED[self.plugin]}")
        if not ca.has_conic(self.plugin):
            raise ImportError(f"CasADi conic plugin {self.plugin!r} does not load")

    def solve_via_data(
        self,
        data: dict[str, Any],
        warm_start: bool,
        verbose: bool,
        solver_opts: dict[str, Any],
        solver_cache: Any = None,
    ) -> Any:
        a = sp.vstack([data[s.A], data[s.F]]).tocsc()
        lba = np.concatenate([data[s.B], np.full(data[s.G].shape, -np.inf)])
        uba = np.concatenate([data[s.B], data[s.G]])
        out, stats, wall = _solve_qp(
            self.plugin, data[s.P], np.asarray(data[s.Q], float), a, lba, uba, dict(solver_opts)
        )
        return {"out": out, "stats": stats, "wall": wall}

    def invert(self, solution: dict[str, Any], inverse_data: dict[str, Any]) -> Solution:
        stats, out = solution["stats"], solution["out"]
        attr: dict[str, Any] = {s.SOLVE_TIME: solution["wall"], s.EXTRA_STATS: stats}
        iters = stats.get("iter_count", stats.get("iter"))
        if isinstance(iters, (int, float)) and iters >= 0:  # -1: plugin does not say
            attr[s.NUM_ITERS] = int(iters)
        x = np.asarray(out["x"], dtype=float).ravel()
        if not stats.get("success", False) or not np.all(np.isfinite(x)):
            unified = str(stats.get("unified_return_status", ""))
            return failure_solution(CONIC_STATUS.get(unified, s.SOLVER_ERROR), attr)
        opt_val = float(out["cost"]) + inverse_data[s.OFFSET]
        primal = {inverse_data[self.VAR_ID]: x}
        # CasADi's λ_a (∇f + Aᵀλ = 0) has CVXPY's sign convention for these rows as is.
        lam = np.asarray(out["lam_a"], dtype=float).ravel()
        n_eq = inverse_data[self.DIMS].zero
        duals = utilities.get_dual_values(
            lam[:n_eq], utilities.extract_dual_value, inverse_data[self.EQ_CONSTR]
        )
        duals |= utilities.get_dual_values(
            lam[n_eq:], utilities.extract_dual_value, inverse_data[self.NEQ_CONSTR]
        )
        return Solution(s.OPTIMAL, opt_val, primal, duals, attr)


#: The status table of every CasADi conic plugin (:data:`CANDIDATE_PLUGINS`): CasADi's
#: plugin-independent ``unified_return_status`` (``casadi_types.hpp``; the plugins' own
#: codes are translated into it by CasADi) of a *failed* call → CVXPY status. Success
#: needs CasADi's ``success`` flag (and finite x), whatever the code; an iteration limit
#: is SOLVER_ERROR (CVXPY's USER_LIMIT expects a primal point to unpack), and so is any
#: code not listed here. Only INFEASIBLE carries a verdict (the plugin's certificate).
CONIC_STATUS: dict[str, str] = {
    "SOLVER_RET_INFEASIBLE": s.INFEASIBLE,
    "SOLVER_RET_LIMITED": s.SOLVER_ERROR,
    "SOLVER_RET_NAN": s.SOLVER_ERROR,
    "SOLVER_RET_EXCEPTION": s.SOLVER_ERROR,
    "SOLVER_RET_UNKNOWN": s.SOLVER_ERROR,
    # reported with success unset (e.g. non-finite x): not a solution either
    "SOLVER_RET_SUCCESS": s.SOLVER_ERROR,
}

#: Plugins left out on purpose, with the reason (shown in the comparison report).
EXCLUDED: dict[str, str] = {
    "highs": "CasADi's libhighs and highspy's (CVXPY's HIGHS interface) in one process "
    "crash ('corrupted double-linked list', seen here with casadi 3.8.2 and highspy); "
    "HiGHS is compared through CVXPY instead",
}

_PROBE = r"""
import sys, casadi as ca, numpy as np
H = ca.DM(2 * np.eye(2)); A = ca.DM([[1, 1], [1, 0]])
for plugin in sys.argv[1:]:
    try:
        if not ca.has_conic(plugin):
            print(plugin, "does not load", flush=True); continue
        S = ca.conic("probe", plugin, {"h": H.sparsity(), "a": A.sparsity()},
                     {"error_on_fail": False})
        out = S(h=H, g=ca.DM.zeros(2), a=A, lba=ca.DM([1, -ca.inf]), uba=ca.DM([1, .8]))
        x = np.asarray(out["x"], dtype=float).ravel()
        err = float(np.max(np.abs(x - 0.5)))
        ok = bool(S.stats().get("success", False)) and err <= 1e-2
        print(plugin, "ok" if ok else f"wrong answer on the test QP (error {err:.1e})",
              flush=True)
    except Exception as exc:
        print(plugin, "error:", str(exc).splitlines()[0][:120], flush=True)
"""


@functools.cache
def probe_plugins() -> dict[str, str]:
    """For each of :data:`CANDIDATE_PLUGINS`: ``"ok"`` if it loads and solves
    ``min x² + y² s.t. x + y = 1, x ≤ 0.8`` to 1e-2, else why not.

    The probe runs in a child process: a plugin that crashes the interpreter (seen here)
    must not take the caller with it. Accuracy is not judged here -- the comparison does
    that; this only keeps out plugins that cannot take the problem class at all.
    """
    todo = [p for p in CANDIDATE_PLUGINS if p not in EXCLUDED]
    res = {**EXCLUDED, **probe_in_child(_PROBE, todo)}
    return {p: res[p] for p in CANDIDATE_PLUGINS}


def casadi_qp_plugins() -> tuple[str, ...]:
    """The CasADi conic plugins that passed :func:`probe_plugins`."""
    return tuple(p for p, v in probe_plugins().items() if v == "ok")
