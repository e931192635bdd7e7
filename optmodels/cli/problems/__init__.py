"""The problems' verbs, one module per problem (``assignment.py``, ``biasfield.py``, ...),
found by :func:`modules`: adding a problem's CLI is adding its module here, no list of
problem names to edit.

A problem module provides

- ``register(sub)``: adds ``optmodels <problem> <verb> ...`` to the top-level
  sub-commands ``sub`` (each verb's ``func`` returns an :data:`~optmodels.cli.contract.Outcome`,
  its ``printer`` prints the human text);
- for ``optmodels demo``: ``DEMO_TITLE`` (its line in report/index.md) and
  ``run_demo(out, args, progress)``, which calls the problem's runner in :mod:`optmodels.demo`;
- for ``optmodels compare --details``: ``run_details(out, *, sizes, runs, repeats, seed,
  progress)`` returning the report section and the result entry.
"""

from __future__ import annotations

from types import ModuleType

from optmodels import registry


def names() -> tuple[str, ...]:
    """The registered problems with a module here, in the registry's order
    (:func:`optmodels.registry.names`: the README's table, plane first) -- the order
    ``optmodels demo`` runs them and lists them in report/index.md."""
    return tuple(p for p in registry.names() if registry.face_module(__name__, p) is not None)


def modules() -> list[ModuleType]:
    """Every problem module of this package, imported, sorted by name (the order of the
    sub-commands in ``optmodels --help``)."""
    return [m for p in sorted(names()) if (m := registry.face_module(__name__, p))]


def with_hook(hook: str) -> dict[str, ModuleType]:
    """The problem modules defining ``hook`` (``run_demo``, ``run_details``) by problem
    name, in the order of :func:`names`."""
    found = {p: registry.face_module(__name__, p) for p in names()}
    return {p: m for p, m in found.items() if m is not None and hasattr(m, hook)}
