"""The registry of problems: the one place that knows which problems exist.

A problem is a package ``optmodels/<name>/`` holding a card ``about.py`` with one literal
``PROBLEM = {...}`` (keys below). :func:`problems` finds the cards with :mod:`pkgutil` and
reads them with :func:`ast.literal_eval`, without importing the package (so ``import
optmodels`` and ``optmodels --help`` stay cheap) and without importing any face.

Every face finds its per-problem module by the problem's name, and iterates :func:`names`:

===============================  =================================================
face                             per-problem module (looked up by name)
===============================  =================================================
``optmodels`` (package)          ``optmodels.<name>`` (lazy attribute, ``__all__``)
``optmodels <name> <verb>``      ``optmodels/cli/problems/<name>.py``
``optmodels demo``               ``optmodels/demo/<name>.py`` (``run_<name>_demo``)
``optmodels compare``            ``solvers_cmp.<name>:Adapter`` (an adapter class in
                                 ``solvers_cmp.cases`` whose ``name`` is the problem's
                                 would be found first; none is left there)
``optmodels compare --details``  ``solvers_cmp.<name>.write_report`` (the report
                                 section; also ``solvers_cmp.report.write_<name>``)
``optmodels montecarlo``         ``optmodels/montecarlo/studies/<name>.py`` (a study
                                 class declaring ``problem = "<name>"``)
===============================  =================================================

Order: the card's ``order`` (the README's table: plane, trajectories, fusion, biasfield,
assignment), then the name. It is the order of ``optmodels demo`` and report/index.md and
of the comparison harness (``optmodels.__all__`` lists the problems alphabetically).

Card keys: ``name`` (the package's name), ``order`` (int), ``paper`` (file under
``shared/papers/``), ``title``, ``original`` (the equations of the original form),
``closed_form`` (the equations of the paper's closed form, or ``None``), and ``api``: the
package's public names for the contract every problem keeps (``tests/test_contract.py``):
``data`` (the validating data class, or ``None`` when the entry points take arrays),
``residuals`` (functions of the original form evaluated in NumPy; a dotted name is looked
up in a submodule, ``selection.objective``), ``solve`` (the generic
solve), ``closed_form`` (the verified closed form, or ``None``) and ``estimate`` (the
solution's attribute holding the estimate; NaN or absent when the status is not OK).
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import pkgutil
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = ["CARD", "Problem", "face_module", "get", "names", "problems"]

#: The card's file name inside a problem package.
CARD = "about.py"

_KEYS = {"name", "order", "paper", "title", "original", "closed_form", "api"}
_API = {"data", "residuals", "solve", "closed_form", "estimate"}


@dataclass(frozen=True)
class Problem:
    """One registered problem, as its card declares it."""

    name: str
    order: int
    paper: str
    title: str
    original: str
    closed_form: str | None
    api: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    @property
    def package(self) -> str:
        return f"optmodels.{self.name}"

    def module(self) -> ModuleType:
        """The problem's package, imported."""
        return importlib.import_module(self.package)

    def entry(self, key: str) -> Any:
        """The object the card's ``api[key]`` names (``None`` if the card says none); for
        ``residuals`` the tuple of functions. (``estimate`` names a solution's attribute,
        not an entry.)"""
        spec = self.api[key]
        if spec is None or key == "estimate":
            return None
        if isinstance(spec, tuple | list):
            return tuple(self._attr(s) for s in spec)
        return self._attr(spec)

    def _attr(self, dotted: str) -> Any:
        mod, _, attr = dotted.rpartition(".")
        owner = importlib.import_module(f"{self.package}.{mod}") if mod else self.module()
        return getattr(owner, attr)


def _read_card(path: Path) -> dict[str, Any]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    for node in tree.body:
        if (
            isinstance(node, ast.Assign)
            and len(node.targets) == 1
            and isinstance(node.targets[0], ast.Name)
            and node.targets[0].id == "PROBLEM"
        ):
            card = ast.literal_eval(node.value)
            if isinstance(card, dict):
                return card
    raise ValueError(f"{path}: no literal PROBLEM = {{...}}")


def _problem(pkg: str, card: dict[str, Any], path: Path) -> Problem:
    if set(card) != _KEYS or card["name"] != pkg or not isinstance(card["order"], int):
        raise ValueError(
            f"{path}: a card has exactly the keys {sorted(_KEYS)}, and its "
            f"name is its package's ({pkg!r})"
        )
    if not isinstance(card["api"], dict) or set(card["api"]) != _API:
        raise ValueError(f"{path}: api has exactly the keys {sorted(_API)}")
    return Problem(**card)


@lru_cache(maxsize=1)
def _discover() -> tuple[Problem, ...]:
    root = Path(__file__).parent
    found = []
    for info in pkgutil.iter_modules([str(root)]):
        card_file = root / info.name / CARD
        if info.ispkg and not info.name.startswith("_") and card_file.is_file():
            found.append(_problem(info.name, _read_card(card_file), card_file))
    return tuple(sorted(found, key=lambda p: (p.order, p.name)))


def problems() -> tuple[Problem, ...]:
    """Every registered problem, in the registry's order."""
    return _discover()


def names() -> tuple[str, ...]:
    """The registered problems' names, in the registry's order."""
    return tuple(p.name for p in _discover())


def get(name: str) -> Problem:
    """The registered problem ``name`` (``KeyError`` naming the known ones otherwise)."""
    for p in _discover():
        if p.name == name:
            return p
    raise KeyError(f"unknown problem {name!r} (registered: {', '.join(names())})")


def face_module(face: str, name: str) -> ModuleType | None:
    """The per-problem module ``<face>.<name>`` of a face (e.g. ``optmodels.demo``,
    ``optmodels.cli.problems``, ``solvers_cmp``), imported; ``None`` if it has none."""
    if importlib.util.find_spec(f"{face}.{name}") is None:
        return None
    return importlib.import_module(f"{face}.{name}")
