"""The case registry of the comparison harness: one adapter per problem.

An adapter knows, for its problem, the *instances* (named generators), what ``size`` means,
how to build a seeded instance, its reference solution (the closed form where the paper
has one, else the best known solution from a high-accuracy solve), the runs
(formulation × solver) that apply, and how to run one and measure it against the
reference. :mod:`solvers_cmp.harness` does the rest (isolation, time limits, resume,
metrics); adapters never time out or catch crashes themselves.

Register your own with :func:`register` (e.g. a new problem or a new instance family): the
adapter class is named by its import path so that worker processes can rebuild it.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np


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
        ok=bool(sol.status.ok), status=sol.status.value,
        objective=float(sol.objective if objective is None else objective),
        x=x if sol.status.ok else None,
        max_violation=float(sol.max_residual),
        build_time=float(sol.build_time or 0.0), solve_time=float(sol.solve_time or 0.0),
        iterations=sol.iterations, message=str(sol.message or "")[:300])


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

    def make(self, instance: str, size: int, seed: int) -> Any:
        raise NotImplementedError

    def reference(self, instance: str, data: Any) -> Outcome:
        raise NotImplementedError

    def runs(self, instance: str) -> list[Run]:
        raise NotImplementedError

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        raise NotImplementedError

    def error(self, x: Any, ref: Any) -> float:
        return _rel_max(np.asarray(x, float), np.asarray(ref, float))


class PlaneAdapter(Adapter):
    """Plane of maneuver (paper 000). size = N points. ``two-source``: D_i = α_i² D, the
    closed form (1.5)-(1.8) is the reference; ``radar``: general D_i (one radar, range
    and angle errors), the reference is the best of three IPOPT starts on the reduced NLP
    at high accuracy. Error: angle between normals (rad)."""

    name = "plane"
    instances = ("two-source", "radar")
    sizes = (20, 100, 1000)
    size_meaning = "points N"
    problem_class = "NLP (equality-constrained, nonconvex)"

    def make(self, instance: str, size: int, seed: int) -> Any:
        from optmodels import plane, scenarios

        rng = np.random.default_rng([seed, size, self.instances.index(instance)])
        sc = (scenarios.two_source_plane(size, rng) if instance == "two-source"
              else scenarios.radar_plane(size, rng, geometry="broadside"))
        return plane.PlaneData(sc.points, sc.cov, sc.alpha2)

    def reference(self, instance: str, data: Any) -> Outcome:
        from optmodels import plane

        if instance == "two-source":
            sol = plane.closed_form(data)
        else:
            sol = plane.solve(data, "reduced", starts=3,
                              ipopt_options={"tol": 1e-12, "constr_viol_tol": 1e-12})
        return _from_solution(sol, sol.normal)

    def runs(self, instance: str) -> list[Run]:
        out = [Run("closed_form", "numpy")] if instance == "two-source" else []
        return out + [Run(f, p) for f in ("full", "reduced") for p in nlp_plugins()]

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        from optmodels import plane

        if run.formulation == "closed_form":
            sol = plane.closed_form(data)
        elif run.solver == "ipopt":
            sol = plane.solve(data, run.formulation, ipopt_options=options or None)  # type: ignore[arg-type]
        else:
            sol = plane.solve(data, run.formulation, plugin=run.solver,  # type: ignore[arg-type]
                              plugin_options=options or None)
        return _from_solution(sol, sol.normal)

    def error(self, x: Any, ref: Any) -> float:
        from optmodels import plane

        return float(plane.angle_error(np.asarray(x), np.asarray(ref)))


class TrajectoriesAdapter(Adapter):
    """Dependent linear trajectories (paper 002). size = points per object, Q = 10
    objects. Instances: the two families of the paper (shared start, shared velocity).
    Reference: the closed forms (8)-(9), (12)-(13). Error on θ relative to max |θ|."""

    name = "trajectories"
    instances = ("diverging", "parallel")
    sizes = (10, 100, 1000)
    size_meaning = "points per object (Q = 10)"
    problem_class = "QP (equality-constrained least squares)"
    objects = 10

    def make(self, instance: str, size: int, seed: int) -> Any:
        from solvers_cmp.trajectories import instance as gen

        return gen(instance, self.objects, size, seed)

    def reference(self, instance: str, data: Any) -> Outcome:
        from optmodels import trajectories as tr

        sol = tr.closed_form(data, instance)  # type: ignore[arg-type]
        return _from_solution(sol, sol.theta)

    def runs(self, instance: str) -> list[Run]:
        return [Run("closed_form", "numpy")] + [
            Run(f, s) for f in ("constrained", "reduced") for s in cvxpy_qp_solvers()]

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        from optmodels import trajectories as tr

        if run.formulation == "closed_form":
            sol = tr.closed_form(data, instance)  # type: ignore[arg-type]
        else:
            sol = tr.solve(data, instance, formulation=run.formulation,  # type: ignore[arg-type]
                           solver=run.solver, **options)
        return _from_solution(sol, sol.theta)


class FusionAdapter(Adapter):
    """Fusion of two estimates (paper 003). ``independent``: the WLS problem in α vs
    (1)-(2); ``correlated``: the minimum-trace weight vs (S1 − S12)D⁺, size = m;
    ``joint-ml``: the two-site ML position fix for T independent measurement rows (size =
    T) by CasADi/IPOPT, against a NumPy Gauss-Newton (the reference; error in units
    of the CRB RMS)."""

    name = "fusion"
    instances = ("independent", "correlated", "joint-ml")
    sizes = (3, 20, 100)
    size_meaning = "dimension m (joint-ml: rows T)"
    problem_class = "QP (unconstrained least squares); joint-ml: NLP"

    def make(self, instance: str, size: int, seed: int) -> Any:
        from optmodels import fusion as fu
        from solvers_cmp.fusion import instance as gen

        if instance == "joint-ml":
            system = fu.TwoSiteSystem.on_baseline()
            x = np.array([8_000.0, 30_000.0])
            z = system.sample(x, size, np.random.default_rng([seed, size]))
            return {"system": system, "z": z,
                    "crb": float(np.sqrt(np.trace(system.crb(x))))}
        return gen(size, seed, instance == "correlated")

    def _fuse(self, d: dict[str, Any], **kw: Any) -> Any:
        from optmodels import fusion as fu

        extra = {"s12": d["s12"]} if "s12" in d else {}
        return fu.fuse(d["a1"], d["s1"], d["a2"], d["s2"], **extra, **kw)

    def reference(self, instance: str, data: Any) -> Outcome:
        if instance == "joint-ml":
            sol = data["system"].joint_ml(data["z"], method="gauss_newton")
            return _from_solution(sol, sol.estimate / data["crb"])
        sol = self._fuse(data)
        return _from_solution(sol, sol.estimate)

    def runs(self, instance: str) -> list[Run]:
        if instance == "joint-ml":
            return [Run("ML", "ipopt")]
        form = "min-trace W" if instance == "correlated" else "weighted LSQ"
        return [Run("closed_form", "numpy")] + [Run(form, s) for s in cvxpy_qp_solvers()]

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        if instance == "joint-ml":
            sol = data["system"].joint_ml(data["z"], options=options or None)
            return _from_solution(sol, sol.estimate / data["crb"])
        if run.formulation == "closed_form":
            sol = self._fuse(data)
        else:
            sol = self._fuse(data, method="cvxpy", solver=run.solver, **options)
        return _from_solution(sol, sol.estimate)

    def error(self, x: Any, ref: Any) -> float:
        a, b = np.asarray(x, float), np.asarray(ref, float)
        if a.ndim == 2:  # joint ML: largest position distance, in CRB units
            return float(np.max(np.linalg.norm(a - b, axis=1)))
        return _rel_max(a, b)


class BiasfieldAdapter(Adapter):
    """Smoothest radar bias field (paper 001, section 4), synthetic uncertainty sets, 4
    radars; size = K cells. ``no-box``: the sparse closed form (11) (sign corrected) is the
    reference; ``box``: the box (8) at 99-99.9 % of the unconstrained field's largest |f|
    (binding), reference = Clarabel on the reduced form at high accuracy. Error per
    component relative to its largest value."""

    name = "biasfield"
    instances = ("no-box", "box")
    sizes = (100, 500, 2000)
    size_meaning = "cells K (4 radars)"
    problem_class = "QP (equality-constrained; box = bound constraints)"

    def make(self, instance: str, size: int, seed: int) -> Any:
        from optmodels import biasfield as bf
        from solvers_cmp.biasfield import binding_box

        data, _ = bf.synthetic_field_data(seed, cells=size)
        box = binding_box(data, bf.closed_form(data)) if instance == "box" else None
        if instance == "box" and box is None:
            from optmodels.core import ProblemError

            raise ProblemError("box: no feasible binding box found for this instance")
        return {"data": data, "box": box}

    def reference(self, instance: str, data: Any) -> Outcome:
        from optmodels import biasfield as bf

        if instance == "no-box":
            sol = bf.closed_form(data["data"])
        else:
            sol = bf.solve(data["data"], box=data["box"], solver="CLARABEL",
                           formulation="reduced", **HIGH_OPTIONS["CLARABEL"])
        return _from_solution(sol, sol.field)

    def runs(self, instance: str) -> list[Run]:
        out = [Run("closed_form", "numpy")] if instance == "no-box" else []
        return out + [Run(f, s) for f in ("constrained", "reduced") for s in cvxpy_qp_solvers()]

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        from optmodels import biasfield as bf

        if run.formulation == "closed_form":
            sol = bf.closed_form(data["data"])
        else:
            sol = bf.solve(data["data"], box=data["box"], solver=run.solver,
                           formulation=run.formulation, **options)  # type: ignore[arg-type]
        return _from_solution(sol, sol.field)

    def error(self, x: Any, ref: Any) -> float:
        a, b = np.asarray(x, float), np.asarray(ref, float)
        return float(np.max(np.abs(a - b).max(axis=(0, 1)) / np.abs(b).max(axis=(0, 1))))


class AssignmentAdapter(Adapter):
    """Joint assignment with unresolved groups (paper 004); size = Q objects, N = Q + Q//8
    + 1 measurements (a clutter share), gate 3σ from Q = 20 on. ``merges``: the joint MILP
    vs the enumeration (14) where it has ≤ 2·10⁵ hypotheses (else the best known: HiGHS at
    zero gap); ``resolved``: merges disallowed, reference = the linear assignment (scipy).
    Error: 0 for the reference's MAP hypothesis, 1 otherwise."""

    name = "assignment"
    instances = ("merges", "resolved")
    sizes = (4, 8, 25)
    size_meaning = "objects Q"
    problem_class = "MILP"
    brute_limit = 200_000

    def make(self, instance: str, size: int, seed: int) -> Any:
        from solvers_cmp.assignment import instance as gen

        gate = 3.0 if size >= 20 else None
        return gen(size, size + size // 8 + 1, seed, gate, merges=instance == "merges")

    @staticmethod
    def _key(sol: Any) -> list[Any]:
        return [sorted(map(list, sol.partition)), list(map(int, sol.assignment))]

    def _out(self, sol: Any) -> Outcome:
        return _from_solution(sol, self._key(sol), objective=sol.log_score)

    def reference(self, instance: str, data: Any) -> Outcome:
        from optmodels import assignment as asg

        if instance == "resolved":
            return self._out(asg.linear_assignment(data))
        if asg.count_hypotheses(data.q, data.n) <= self.brute_limit:
            return self._out(asg.brute_force(data))
        return self._out(asg.solve(data, solver="HIGHS"))

    def runs(self, instance: str) -> list[Run]:
        from optmodels import assignment as asg  # noqa: F401

        out = [Run("joint MILP", s) for s in cvxpy_milp_solvers()]
        if instance == "resolved":
            out.insert(0, Run("linear assignment", "scipy"))
        else:
            out.insert(0, Run("enumeration (14)", "python"))
        return out

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        from optmodels import assignment as asg
        from optmodels.core import ProblemError

        if run.formulation == "linear assignment":
            return self._out(asg.linear_assignment(data))
        if run.formulation == "enumeration (14)":
            if asg.count_hypotheses(data.q, data.n) > self.brute_limit:
                raise ProblemError(f"enumeration: {asg.count_hypotheses(data.q, data.n):.3g} "
                                   f"hypotheses, above the limit {self.brute_limit:.0e}")
            return self._out(asg.brute_force(data))
        return self._out(asg.solve(data, solver=run.solver, **options))

    def error(self, x: Any, ref: Any) -> float:
        return 0.0 if x == ref else 1.0


#: High-accuracy options per solver (the ``high`` profile): the back-end's table
#: :data:`optmodels.backends.profiles.HIGH_OPTIONS` (the same object). Keys are the solvers' own.
HIGH_OPTIONS: dict[str, dict[str, Any]] = importlib.import_module(
    "optmodels.backends.profiles").HIGH_OPTIONS


def _adapter_path(problem: str) -> str | None:
    """Where the adapter of a registered problem is, found by the problem's name: a class
    of this module whose ``name`` is the problem's, else ``solvers_cmp.<problem>:Adapter``
    (the place of a new problem's adapter: one file, no list to edit); ``None`` if neither
    exists. Nothing is imported here (``find_spec`` only)."""
    import importlib.util

    here = [c for c in globals().values() if isinstance(c, type) and issubclass(c, Adapter)
            and c.__module__ == __name__ and c.name == problem]
    if here:
        return f"{__name__}:{here[0].__name__}"
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
        raise ProblemError(f"compare problems: unknown problem {name!r} "
                           f"(known: {sorted(REGISTRY)})")
    mod, _, cls = spec.partition(":")
    found = getattr(importlib.import_module(mod), cls, None)
    if found is None:
        raise ProblemError(f"compare problems: {name!r} has no adapter ({spec} not found)")
    return found()


def known_problems() -> Sequence[str]:
    """The problems with an adapter, in the registry's order (then those added by
    :func:`register`)."""
    return tuple(REGISTRY)
