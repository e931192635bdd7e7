"""The contract every registered problem keeps (issue 15): for each problem of
:mod:`optmodels.registry` -- data validation (bad input: one ``ProblemError`` naming the
problem), the original form's residuals in NumPy, a generic solve, a verified closed form
(where the paper has one, cross-checked against the generic solve), a CLI verb, a demo and
a harness adapter. A new problem is tested by registering it: there is no list here."""

from __future__ import annotations

import inspect
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from optmodels import registry
from optmodels.core import ProblemError
from solvers_cmp import cases as cs
from tests.conftest import assert_verified

PROBLEMS = registry.names()


def _instance(ad: cs.Adapter, closed: bool) -> str:
    """The adapter's first instance with (``closed``) or without a closed-form run."""
    for inst in ad.instances:
        if (cs.Run("closed_form", "numpy") in ad.runs(inst)) == closed:
            return inst
    return ad.instances[0]


def _generic(ad: cs.Adapter, inst: str) -> cs.Run:
    """The first run of a generic solver (not a closed form, not an enumeration)."""
    return next(
        r
        for r in ad.runs(inst)
        if r.formulation != "closed_form" and r.solver not in ("numpy", "python")
    )


def _solutions(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The package solutions the adapters hand to the harness, recorded."""
    seen: list[Any] = []
    orig = cs._from_solution

    def spy(sol: Any, *args: Any, **kw: Any) -> cs.Outcome:
        seen.append(sol)
        return orig(sol, *args, **kw)

    monkeypatch.setattr(cs, "_from_solution", spy)
    return seen


def test_registry_is_discovered_in_its_documented_order() -> None:
    import optmodels

    assert PROBLEMS == ("plane", "trajectories", "fusion", "biasfield", "assignment")
    assert [p.order for p in registry.problems()] == sorted(p.order for p in registry.problems())
    assert set(PROBLEMS) <= set(optmodels.__all__)
    for p in registry.problems():
        assert p.paper in (p.module().__doc__ or ""), p.name  # the docstring cites its paper
    # every face lists exactly the registry, in its order
    from optmodels.cli import problems as cli_problems
    from optmodels.demo import runners
    from optmodels.montecarlo import STUDIES

    assert cli_problems.names() == PROBLEMS
    assert tuple(runners()) == PROBLEMS
    assert tuple(cs.known_problems()) == PROBLEMS
    assert tuple(s.problem for s in STUDIES.values()) == PROBLEMS
    assert list(STUDIES) == [
        "plane-angle",
        "trajectories-eta",
        "fusion-weight",
        "biasfield-recovery",
        "assignment-separation",
    ]


def test_import_optmodels_imports_no_problem() -> None:
    code = (
        "import sys, optmodels; print(sorted(m for m in sys.modules if m.split('.')[:2] "
        "in [['optmodels', p] for p in optmodels.__all__]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"
    code = "from optmodels import plane, assignment; print(plane.solve, assignment.solve)"
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


@pytest.mark.parametrize("name", PROBLEMS)
def test_bad_input_is_one_problem_error(name: str) -> None:
    """Wrong-typed data (or a NaN in an array argument) -> ProblemError naming the problem."""
    prob = registry.get(name)
    ad = cs.adapter(name)
    entries = [e for e in (prob.entry("solve"), prob.entry("closed_form")) if e is not None]
    data = ad.make(ad.instances[0], ad.sizes[0], 0)
    for fn in entries:
        if prob.api["data"] is None:  # the entry takes arrays: the instance is its arguments
            args = {
                k: np.array(v, dtype=float, copy=True)
                for k, v in data.items()
                if isinstance(v, np.ndarray)
            }
            first = next(iter(args))
            args[first].flat[0] = np.nan
            call = lambda fn=fn, args=args: fn(**args)  # noqa: E731
        else:
            params = [
                p
                for p in inspect.signature(fn).parameters.values()
                if p.default is p.empty and p.kind == p.POSITIONAL_OR_KEYWORD
            ]
            rest = [ad.instances[0]] * (len(params) - 1)
            call = lambda fn=fn, rest=rest: fn(object(), *rest)  # noqa: E731
        with pytest.raises(ProblemError, match=rf"^{name}\b"):
            call()


@pytest.mark.parametrize("name", PROBLEMS)
def test_original_form_and_generic_solve(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The card's NumPy functions exist; a generic solve is verified against its residuals."""
    prob = registry.get(name)
    assert all(callable(f) for f in prob.entry("residuals"))
    assert prob.api["data"] is None or isinstance(prob.entry("data"), type)
    ad = cs.adapter(name)
    inst = _instance(ad, closed=prob.closed_form is not None)
    data = ad.make(inst, ad.sizes[0], 1)
    seen = _solutions(monkeypatch)
    out = ad.solve(inst, data, _generic(ad, inst), {})
    assert len(seen) == 1 and seen[0].residuals, seen
    assert_verified(seen[0], data, estimate=prob.api["estimate"])
    assert out.ok, (out.status, out.message)


@pytest.mark.parametrize("name", PROBLEMS)
def test_closed_form_is_verified_and_agrees(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the paper has a closed form: it is verified and equals the generic solve."""
    prob = registry.get(name)
    ad = cs.adapter(name)
    inst = _instance(ad, closed=True)
    has_run = cs.Run("closed_form", "numpy") in ad.runs(inst)
    assert has_run == (prob.closed_form is not None)
    if not has_run:
        return
    data = ad.make(inst, ad.sizes[0], 2)
    seen = _solutions(monkeypatch)
    closed = ad.solve(inst, data, cs.Run("closed_form", "numpy"), {})
    generic = ad.solve(inst, data, _generic(ad, inst), {})
    assert seen[0].method == "closed_form", seen[0].method
    assert_verified(seen[0], data, estimate=prob.api["estimate"])
    assert closed.ok and generic.ok
    assert ad.error(generic.x, closed.x) < 1e-4


@pytest.mark.parametrize("name", PROBLEMS)
def test_cli_verb_demo_and_adapter(name: str) -> None:
    """A CLI verb (``optmodels <name> <verb> --help``), a demo, a harness adapter."""
    import argparse

    from optmodels import cli
    from optmodels.cli import problems as cli_problems
    from optmodels.demo import runners

    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert name in sub.choices
    verbs = next(a for a in sub.choices[name]._actions if isinstance(a, argparse._SubParsersAction))
    assert verbs.choices, name
    mod = cli_problems.with_hook("run_demo")[name]
    assert isinstance(mod.DEMO_TITLE, str) and mod.DEMO_TITLE.startswith("- ")
    assert callable(runners()[name])
    ad = cs.adapter(name)
    assert isinstance(ad, cs.Adapter) and ad.name == name and ad.instances and ad.sizes


# --------------------------------------------------------------------------- the skeleton
#: Where a package is not yet in the skeleton of docs/architecture.md ("Adding a problem"),
#: with what is left to do; the test fails when an entry is no longer a deviation, so that
#: the list only shrinks.
PENDING_SKELETON: dict[tuple[str, str], str] = {}


def _skeleton_deviations(name: str) -> set[str]:
    """The roles of the skeleton that package ``name`` does not fill as documented."""
    import importlib

    from optmodels.core import Solution

    p = registry.get(name)
    pkg = p.module().__name__

    def module(role: str) -> Any:
        try:
            return importlib.import_module(f"{pkg}.{role}")
        except ModuleNotFoundError:
            return None

    bad: set[str] = set()
    data_cls = p.entry("data")
    if data_cls is not None and data_cls.__module__ != f"{pkg}.data":
        bad.add("data")
    sol = module("solution")
    if (
        sol is None
        or not callable(getattr(sol, "_failure", None))
        or not any(
            isinstance(c, type) and issubclass(c, Solution) and c.__module__ == sol.__name__
            for c in vars(sol).values()
        )
    ):
        bad.add("solution")
    ver = module("verify")
    fin = getattr(ver, "_finish", None)
    if fin is None or fin.__module__ != f"{pkg}.verify" or "finish(" not in inspect.getsource(fin):
        bad.add("verify._finish")
    if (
        p.entry("closed_form") is not None
        and p.entry("closed_form").__module__ != f"{pkg}.closedform"
    ):
        bad.add("closedform")
    if p.entry("solve").__module__ != f"{pkg}.generic":
        bad.add("generic.solve")
    return bad


@pytest.mark.parametrize("name", PROBLEMS)
def test_every_problem_package_has_the_one_skeleton(name: str) -> None:
    """docs/architecture.md, "Adding a problem": ``data.py`` (the data class),
    ``solution.py`` (the Solution subclass and its failure form ``_failure``),
    ``verify.py`` (the re-check and the gate ``_finish``, ending in ``core.finish``),
    ``closedform.py`` (``closed_form``, where the paper has one), ``generic.py`` (the
    generic ``solve``); known deviations are listed in ``PENDING_SKELETON``."""
    bad = _skeleton_deviations(name)
    pending = {role for (n, role) in PENDING_SKELETON if n == name}
    assert bad - pending == set(), f"{name}: not in the skeleton: {sorted(bad - pending)}"
    assert pending - bad == set(), (
        f"{name}: {sorted(pending - bad)} now fill the skeleton; remove them from PENDING_SKELETON"
    )


# --------------------------------------------------------------------------- private names
#: Known imports of a private name across packages, in files of other owners (issue 23):
#: each to be made public or removed, then deleted here.
PENDING_PRIVATE: dict[str, set[str]] = {}


def _package(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "optmodels" and len(parts) > 1 else parts[0]


def _private_imports() -> dict[str, set[str]]:
    """``{file: {"<module>.<_name>"}}``: private names that a module of ``optmodels`` or
    ``solvers_cmp`` imports (``from m import _x``) or reads (``m._x`` on an imported module)
    from another package (``optmodels.<pkg>`` or ``solvers_cmp``). Within a package its
    modules share their privates."""
    import ast
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    aliases_of: dict[str, str] = {}  # module aliases of a package __init__ (none now)

    def is_module(name: str) -> bool:
        try:
            return importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            return False

    found: dict[str, set[str]] = {}
    for path in sorted(
        [*root.joinpath("optmodels").rglob("*.py"), *root.joinpath("solvers_cmp").rglob("*.py")]
    ):
        rel = path.relative_to(root)
        mod = ".".join(rel.with_suffix("").parts).removesuffix(".__init__")
        tree = ast.parse(path.read_text(encoding="utf-8"))
        modules: dict[str, str] = {}
        hits: set[str] = set()
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.ImportFrom)
                and node.level == 0
                and node.module
                and node.module.split(".")[0] in ("optmodels", "solvers_cmp")
            ):
                for a in node.names:
                    full = f"{node.module}.{a.name}"
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        if _package(node.module) != _package(mod):
                            hits.add(full)
                    elif a.name in aliases_of or is_module(full):
                        modules[a.asname or a.name] = aliases_of.get(a.name, full)
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] in ("optmodels", "solvers_cmp") and a.asname:
                        modules[a.asname] = a.name
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id in modules
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
                and _package(modules[node.value.id]) != _package(mod)
            ):
                hits.add(f"{modules[node.value.id]}.{node.attr}")
        if hits:
            found[str(rel)] = hits
    return found


def test_no_private_name_crosses_a_package() -> None:
    found = _private_imports()
    new = {f: h - PENDING_PRIVATE.get(f, set()) for f, h in found.items()}
    assert {f: h for f, h in new.items() if h} == {}
    stale = {f: h - found.get(f, set()) for f, h in PENDING_PRIVATE.items()}
    assert {f: h for f, h in stale.items() if h} == {}, "remove these from PENDING_PRIVATE"


def test_no_package_init_reexports_a_private_name() -> None:
    """No ``__init__.py`` of optmodels or solvers_cmp imports a private name (``from m import
    _x``, dunders aside) to hand it on (issue 23): its users import it from its module. An
    ``__init__`` may import one that its own functions call (``cli.main`` runs ``_execute``),
    outside its ``__all__``."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    found: dict[str, list[str]] = {}
    for package in ("optmodels", "solvers_cmp"):
        for path in sorted((root / package).rglob("__init__.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            exported: set[str] = set()
            for node in tree.body:
                if (
                    isinstance(node, ast.Assign | ast.AnnAssign)
                    and any(
                        isinstance(t, ast.Name) and t.id == "__all__"
                        for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
                    )
                    and isinstance(node.value, ast.List | ast.Tuple)
                ):
                    exported |= {
                        e.value
                        for e in node.value.elts
                        if isinstance(e, ast.Constant) and isinstance(e.value, str)
                    }
            used = {
                n.id
                for f in ast.walk(tree)
                if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
                for n in ast.walk(f)
                if isinstance(n, ast.Name)
            }
            for node in ast.walk(tree):
                if not isinstance(node, ast.ImportFrom):
                    continue
                for a in node.names:
                    bound = a.asname or a.name
                    if (
                        a.name.startswith("_")
                        and not a.name.startswith("__")
                        and (bound not in used or bound in exported)
                    ):
                        module = "." * node.level + (node.module or "")
                        rel = path.relative_to(root).as_posix()
                        found.setdefault(rel, []).append(f"{module}.{a.name}")
    assert found == {}, "import these from their modules, not through the package"


# --------------------------------------------------------------------------- sizes
#: docs/architecture.md ("Adding a problem"): no module over 600 lines, no function over 150
#: (issue 23 item 6), counted on the formatted source (``ruff format`` in ``make test``).
MAX_MODULE_LINES, MAX_FUNCTION_LINES = 600, 150


def test_no_module_over_600_lines_and_no_function_over_150() -> None:
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    long_modules, long_functions = [], []
    for package in ("optmodels", "solvers_cmp"):
        for path in sorted((root / package).rglob("*.py")):
            text = path.read_text(encoding="utf-8")
            rel = path.relative_to(root).as_posix()
            if text.count("\n") > MAX_MODULE_LINES:
                long_modules.append((rel, text.count("\n")))
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    size = (node.end_lineno or node.lineno) - node.lineno + 1
                    if size > MAX_FUNCTION_LINES:
                        long_functions.append((rel, node.name, size))
    assert long_modules == [], f"modules over {MAX_MODULE_LINES} lines: {long_modules}"
    assert long_functions == [], f"functions over {MAX_FUNCTION_LINES} lines: {long_functions}"
