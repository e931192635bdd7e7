"""The sweep plan of the comparison harness and its argument checks.

:class:`Case` (problem, instance, size, seed), :func:`plan` (adapter path, case and runs
for every problem × instance × size × seed, the names and numbers checked: ``_names``,
``_counts``); the scheduler is checked by :func:`optmodels.execution.as_scheduler`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from optmodels.core import ProblemError, as_count
from solvers_cmp import cases as cs


@dataclass(frozen=True)
class Case:
    problem: str
    instance: str
    size: int
    seed: int


Sizes = Sequence[int] | Mapping[str, Sequence[int]] | None


def _names(what: str, v: Any) -> list[str] | None:
    """A list of names from a list (or one string); None stays None."""
    if v is None:
        return None
    items = [v] if isinstance(v, str) else v
    if not isinstance(items, Sequence | set | frozenset) or not all(
        isinstance(x, str) for x in items
    ):
        raise ProblemError(f"{what}: expected a list of names, got {v!r}"[:200])
    items = [x.strip() for x in items if x.strip()]
    if not items:
        raise ProblemError(f"{what}: expected at least one name, got {v!r}")
    return items


def _counts(what: str, v: Any, minimum: int) -> list[int]:
    if isinstance(v, str) or not isinstance(v, Sequence | range):
        raise ProblemError(f"{what}: expected a list of whole numbers, got {v!r}"[:200])
    out = [as_count(what, x, minimum=minimum) for x in v]
    if not out:
        raise ProblemError(f"{what}: expected at least one value, got {v!r}")
    return out


def plan(
    problems: Sequence[str],
    sizes: Sizes = None,
    solvers: Sequence[str] | None = None,
    seeds: Sequence[int] = (0,),
    instances: Sequence[str] | None = None,
) -> list[tuple[str, Case, list[cs.Run]]]:
    """The sweep: (adapter path, case, runs) for every problem × instance × size × seed.
    ``sizes``: one list for every problem, or a list per problem name (missing names and
    ``None``: the adapter's default sizes). ``solvers`` filters runs by solver name
    (case-insensitive); the closed-form rows are always kept (they are the floor of every
    plot).

    Raises
    ------
    ProblemError
        An unknown problem, or a solver or instance name that none of the problems has
        (the message lists the known ones), sizes < 1, seeds < 0.
    """
    problems = _names("compare problems", problems) or []
    solvers = _names("compare solvers", solvers)
    instances = _names("compare instances", instances)
    seeds = _counts("compare seeds", seeds, 0)
    if isinstance(sizes, Mapping):
        sizes = {
            str(k): _counts(f"compare sizes[{k!r}]", v, 1)
            for k, v in sizes.items()
            if v is not None
        }
    elif sizes is not None:
        sizes = _counts("compare sizes", sizes, 1)
    ads = {p: cs.adapter(p) for p in problems}  # ProblemError for an unknown problem
    if instances:
        known_inst = {i for ad in ads.values() for i in ad.instances}
        bad = [i for i in instances if i not in known_inst]
        if bad:
            raise ProblemError(
                f"compare instances: unknown instance(s) {bad} of "
                f"{', '.join(problems)} (known: {sorted(known_inst)})"
            )
    want = {x.lower() for x in solvers} if solvers else None
    if want is not None:
        known = {
            r.solver
            for ad in ads.values()
            for inst in ad.instances
            if not instances or inst in instances
            for r in ad.runs(inst)
        }
        bad = [x for x in solvers or () if x.lower() not in {k.lower() for k in known}]
        if bad:
            raise ProblemError(
                f"compare solvers: unknown solver(s) {bad} for "
                f"{', '.join(problems)} (available here: {sorted(known)})"
            )
    out = []
    for p, ad in ads.items():
        path = cs.REGISTRY.get(p)
        assert path is not None
        for inst in ad.instances:
            if instances and inst not in instances:
                continue
            runs = [
                r
                for r in ad.runs(inst)
                if want is None or r.formulation == "closed_form" or r.solver.lower() in want
            ]
            own = sizes.get(p) if isinstance(sizes, Mapping) else sizes
            for size in own or ad.sizes:
                for seed in seeds:
                    out.append((path, Case(p, inst, int(size), int(seed)), runs))
    return out
