"""The case registry of the comparison harness: one adapter per problem.

An adapter knows, for its problem, the *instances* (named generators), what ``size`` means,
how to build a seeded instance, its reference solution (the closed form where the paper
has one, else the best known solution from a high-accuracy solve), the runs
(formulation × solver) that apply, and how to run one and measure it against the
reference. :mod:`solvers_cmp.harness` does the rest (isolation, time limits, resume,
metrics); adapters never time out or catch crashes themselves.

This module holds what every adapter shares (:class:`Adapter`, :class:`Outcome`,
:class:`Run`, the solver lists, :func:`_from_solution`, :data:`HIGH_OPTIONS`), what the
face files' ``compare --details`` rows and tables share (:func:`timed_solves`,
:func:`details_row`, :func:`details_table`) and the registry.
Each problem's adapter is ``class Adapter(cases.Adapter)`` in its face file
``solvers_cmp/<problem>.py``, found by the problem's name (:func:`_adapter_path`): adding
a problem adds one file, no list here. Register your own with :func:`register` (e.g. a
new problem or a new instance family): the adapter class is named by its import path so
that worker processes can rebuild it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from solvers_cmp.common import repeat


#: Solution-comparison outcome of one run.
@dataclass
class Outcome:
    """One run's result, reduced to what the harness records.

    ``x`` is the vector compared with the reference (normal, θ, α, field, hypothesis key);
    ``ok`` the solver's own verdict after the package's NumPy re-check.
    """

    ok: bool
    status: str
    objective: float
    x: Any
    max_violation: float
    build_time: float
    solve_time: float
    iterations: int | None = None
    message: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Run:
    """A formulation × solver pair; ``reference=True`` marks the closed form."""

    formulation: str
    solver: str


# ----------------------------------------------------------------------- solver lists
def cvxpy_qp_solvers() -> list[str]:
    """CVXPY solvers installed here that take a convex QP (CVXPY's QP interfaces plus the
    conic ones that take a quadratic objective), then the CasADi conic plugins that pass
    :func:`optmodels.backends.casadi_qp.probe_plugins`, as ``CASADI_<PLUGIN>``."""
    import cvxpy as cp
    from cvxpy.reductions.solvers import defines

    from optmodels.backends.casadi_qp import casadi_qp_plugins

    installed = cp.installed_solvers()
    conic_qp = ("CLARABEL", "SCS", "ECOS", "QOCO", "CVXOPT", "MOSEK", "GUROBI", "CPLEX")
    qp = [s for s in installed if s in defines.QP_SOLVERS or s in conic_qp]
    order = ["CLARABEL", "OSQP", "SCS", "HIGHS"]
    qp.sort(key=lambda s: (order.index(s) if s in order else len(order), s))
    return qp + [f"CASADI_{p.upper()}" for p in casadi_qp_plugins()]


def cvxpy_milp_solvers() -> list[str]:
    """CVXPY solvers installed here that take a mixed-integer LP."""
    import cvxpy as cp
    from cvxpy.reductions.solvers import defines

    return [s for s in cp.installed_solvers() if s in defines.MI_SOLVERS]


def nlp_plugins() -> list[str]:
    """CasADi NLP plugins that load and solve a test NLP here."""
    from optmodels.backends.casadi_backend import nlp_plugins as plugins

    return list(plugins())


def _rel_max(a: np.ndarray, b: np.ndarray) -> float:
    scale = float(np.max(np.abs(b)))
    return float(np.max(np.abs(np.asarray(a) - b))) / (scale if scale > 0 else 1.0)


def _from_solution(sol: Any, x: Any, objective: float | None = None) -> Outcome:
    return Outcome(
        ok=bool(sol.status.ok),
        status=sol.status.value,
        objective=float(sol.objective if objective is None else objective),
        x=x if sol.status.ok else None,
        max_violation=float(sol.max_residual),
        build_time=float(sol.build_time or 0.0),
        solve_time=float(sol.solve_time or 0.0),
        iterations=sol.iterations,
        message=str(sol.message or "")[:300],
    )


# ------------------------------------------------ the compare --details rows and tables
#: One run of a face file's ``rows``: (formulation, solver, solution, build time, solve
#: time), times in s.
TimedRun = tuple[str, str, Any, float, float]


def timed_solves(formulation: str, solver: str, fn: Callable[[], Any], repeats: int) -> TimedRun:
    """``repeats`` calls of the generic solve ``fn``: the last solution, with the median
    of the solutions' own build and solve times."""
    sols = repeat(fn, repeats).results
    return (
        formulation,
        solver,
        sols[-1],
        float(np.median([x.build_time for x in sols])),
        float(np.median([x.solve_time for x in sols])),
    )


def details_row(
    head: dict[str, Any],
    run: TimedRun,
    ref: Any,
    error: Callable[[Any, Any], float],
    extra: Callable[[Any], dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """A ``compare --details`` row, in the report's column order: ``head`` (what the
    instance is), the run's formulation and solver, settings, status, objective,
    ``objective_gap`` (relative to the absolute value of the reference's objective) and
    ``solution_error`` (``error(solution, ref)``) -- NaN unless the solution is OK and
    there is a reference ``ref`` --, ``max_violation``, then ``extra(solution)`` (e.g.
    ``active_bounds``), build, solve and total time (s) and iterations."""
    form, solver, sol, build, solve = run
    good = bool(sol.status.ok) and ref is not None
    return {
        **head,
        "formulation": form,
        "solver": solver,
        "settings": "default",
        "status": sol.status.value,
        "objective": sol.objective,
        "objective_gap": (sol.objective - ref.objective) / abs(ref.objective)
        if good
        else float("nan"),
        "solution_error": error(sol, ref) if good else float("nan"),
        "max_violation": sol.max_residual,
        **(extra(sol) if extra is not None else {}),
        "build_time": build,
        "solve_time": solve,
        "total_time": build + solve,
        "iterations": sol.iterations,
    }


def details_table(
    rows: list[dict[str, Any]],
    lead: Sequence[str],
    *,
    extra: Sequence[str] = (),
    time_digits: str = ".4f",
) -> str:
    """The Markdown table of a ``compare --details`` section: the columns ``lead`` (what
    the instance is), formulation, solver, status, the errors (``.1e``), ``extra``, build
    and solve time (``time_digits``) and iterations."""
    from optmodels.io import markdown_table

    cols = [
        *lead,
        "formulation",
        "solver",
        "status",
        "solution_error",
        "objective_gap",
        "max_violation",
        *extra,
        "build_time",
        "solve_time",
        "iterations",
    ]
    fmt = {
        "solution_error": ".1e",
        "objective_gap": ".1e",
        "max_violation": ".1e",
        "build_time": time_digits,
        "solve_time": time_digits,
    }
    return markdown_table(rows, cols, fmt)


# ---------------------------------------------------------------------------- adapters
class Adapter:
    """Base class. Subclasses set ``name``, ``instances``, ``sizes`` (default sizes),
    ``size_meaning`` and implement :meth:`make`, :meth:`reference`, :meth:`runs`,
    :meth:`solve`; :meth:`error` defaults to max |x − x_ref| / max |x_ref|."""

    name: str = ""
    instances: tuple[str, ...] = ()
    sizes: tuple[int, ...] = ()
    size_meaning: str = ""
    problem_class: str = ""
    #: Formulations that are the floor (exact answers, not generic solves): the closed
    #: form, the exact enumeration. Ranked in their own rows, never in the headline.
    reference_formulations: tuple[str, ...] = ("closed_form",)
    #: Formulations that are reductions of the original problem (a reduced form, a
    #: special case such as the linear assignment without merges): their own rows.
    reductions: tuple[str, ...] = ()

    def notes(self, instance: str, data: Any, ref: Outcome) -> dict[str, Any]:
        """What the report says about an instance (e.g. the MAP's merges); none here."""
        return {}

    def make(self, instance: str, size: int, seed: int) -> Any:
        raise NotImplementedError

    def truth(self, instance: str, size: int, seed: int, data: Any) -> tuple[Any, float] | None:
        """For the statistical-efficiency column (issue 27, item 6): the true parameter of
        the seeded draw ``make(instance, size, seed)`` in the space of ``Outcome.x`` and the
        Cramér–Rao bound on the expected squared error E :meth:`sq_error` (x̂, truth) of an
        unbiased estimate, same units; None (here) where the instance is not a draw from
        a known truth or has no bound."""
        return None

    def sq_error(self, x: Any, truth: Any) -> float:
        """Squared estimation error of one draw, ‖x − truth‖² (the units of
        :meth:`truth`'s bound)."""
        d = np.asarray(x, float) - np.asarray(truth, float)
        return float(np.sum(d * d))

    def reference(self, instance: str, data: Any) -> Outcome:
        raise NotImplementedError

    def runs(self, instance: str) -> list[Run]:
        raise NotImplementedError

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        raise NotImplementedError

    def error(self, x: Any, ref: Any) -> float:
        return _rel_max(np.asarray(x, float), np.asarray(ref, float))


#: High-accuracy options per solver (the ``high`` profile): the back-end's table
#: :data:`optmodels.backends.profiles.HIGH_OPTIONS` (the same object). Keys are the solvers' own.
HIGH_OPTIONS: dict[str, dict[str, Any]] = importlib.import_module(
    "optmodels.backends.profiles"
).HIGH_OPTIONS


def _adapter_path(problem: str) -> str | None:
    """Where the adapter of a registered problem is, found by the problem's name:
    ``solvers_cmp.<problem>:Adapter`` (one file per problem, no list to edit); ``None`` if
    there is no such module. Nothing is imported here (``find_spec`` only)."""
    import importlib.util

    if importlib.util.find_spec(f"solvers_cmp.{problem}") is not None:
        return f"solvers_cmp.{problem}:Adapter"
    return None


def _discover() -> dict[str, str]:
    from optmodels import registry

    found = {p: _adapter_path(p) for p in registry.names()}
    return {p: path for p, path in found.items() if path is not None}


#: Adapters by problem name → "module:Class": every problem of :mod:`optmodels.registry`
#: with an adapter (:func:`_adapter_path`), in the registry's order; :func:`register` adds
#: others (e.g. a test's adapter).
REGISTRY: dict[str, str] = _discover()


def register(name: str, path: str) -> None:
    """Register an adapter class by import path ``"package.module:Class"``."""
    REGISTRY[name] = path


def adapter(name: str, path: str | None = None) -> Adapter:
    """Instantiate the adapter registered as ``name`` (or at ``path``)."""
    from optmodels.core import ProblemError

    spec = path or REGISTRY.get(name)
    if spec is None:
        raise ProblemError(
            f"compare problems: unknown problem {name!r} (known: {sorted(REGISTRY)})"
        )
    mod, _, cls = spec.partition(":")
    found = getattr(importlib.import_module(mod), cls, None)
    if found is None:
        raise ProblemError(f"compare problems: {name!r} has no adapter ({spec} not found)")
    return found()


def known_problems() -> Sequence[str]:
    """The problems with an adapter, in the registry's order (then those added by
    :func:`register`)."""
    return tuple(REGISTRY)
