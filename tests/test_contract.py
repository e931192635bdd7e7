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
    return next(r for r in ad.runs(inst)
                if r.formulation != "closed_form" and r.solver not in ("numpy", "python"))


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
    assert list(STUDIES) == ["plane-angle", "trajectories-eta", "fusion-weight",
                             "biasfield-recovery", "assignment-separation"]


def test_import_optmodels_imports_no_problem() -> None:
    code = ("import sys, optmodels; print(sorted(m for m in sys.modules if m.split('.')[:2] "
            "in [['optmodels', p] for p in optmodels.__all__]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
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
            args = {k: np.array(v, dtype=float, copy=True) for k, v in data.items()
                    if isinstance(v, np.ndarray)}
            first = next(iter(args))
            args[first].flat[0] = np.nan
            call = lambda fn=fn, args=args: fn(**args)  # noqa: E731
        else:
            params = [p for p in inspect.signature(fn).parameters.values()
                      if p.default is p.empty and p.kind == p.POSITIONAL_OR_KEYWORD]
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
    verbs = next(a for a in sub.choices[name]._actions
                 if isinstance(a, argparse._SubParsersAction))
    assert verbs.choices, name
    mod = cli_problems.with_hook("run_demo")[name]
    assert isinstance(mod.DEMO_TITLE, str) and mod.DEMO_TITLE.startswith("- ")
    assert callable(runners()[name])
    ad = cs.adapter(name)
    assert isinstance(ad, cs.Adapter) and ad.name == name and ad.instances and ad.sizes
