"""``optmodels demo``: the papers' examples, with figures and a short report each.

One module per registered problem (:mod:`optmodels.registry`), ``optmodels/demo/<name>.py``,
whose entry is ``run_<name>_demo(out, ...)``. The entries are found by name and imported on
first use (``from optmodels.demo import run_plane_demo``): adding a problem's demo is adding
its module here, no list to edit.
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import Any

from optmodels import registry


def _entry(name: str) -> str:
    return f"run_{name}_demo"


def runners() -> dict[str, Any]:
    """Each registered problem's demo entry by problem name, in the registry's order."""
    mods = {p: registry.face_module(__name__, p) for p in registry.names()}
    return {
        p: getattr(m, _entry(p)) for p, m in mods.items() if m is not None and hasattr(m, _entry(p))
    }


def _with_module() -> list[str]:
    return [p for p in registry.names() if importlib.util.find_spec(f"{__name__}.{p}")]


def __getattr__(attr: str) -> Any:
    """``run_<name>_demo`` of a registered problem, from its module here."""
    for p in _with_module():
        if attr == _entry(p):
            return getattr(registry.face_module(__name__, p), attr)
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")


__all__ = sorted([*(_entry(p) for p in _with_module()), "runners"])
