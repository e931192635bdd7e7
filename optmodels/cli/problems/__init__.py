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

import importlib
import pkgutil
from types import ModuleType


def _found() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def modules() -> list[ModuleType]:
    """Every problem module of this package, imported, sorted by name."""
    return [importlib.import_module(f"{__name__}.{name}") for name in _found()]


def names() -> tuple[str, ...]:
    """The problems with a module here, in the registry's order (:func:`optmodels.registry.names`:
    the README's table, plane first) -- the order ``optmodels demo`` runs them and lists them
    in report/index.md; a module here of a problem the registry does not know comes after,
    by name."""
    from optmodels import registry

    order = {p: i for i, p in enumerate(registry.names())}
    return tuple(sorted(_found(), key=lambda p: (order.get(p, len(order)), p)))


def with_hook(hook: str) -> dict[str, ModuleType]:
    """The problem modules defining ``hook`` (``run_demo``, ``run_details``) by problem
    name, in the order of :func:`names`."""
    mods = {name: importlib.import_module(f"{__name__}.{name}") for name in _found()}
    return {p: mods[p] for p in names() if hasattr(mods[p], hook)}
