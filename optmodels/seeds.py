"""The one seed helper of the package: a seed argument → a ``numpy.random.Generator``.

Every ``_rng`` of the problems and scenarios goes through :func:`as_generator`, so a seed
means the same everywhere: a ``Generator`` is used as given, a whole number ≥ 0 (or a
sequence of them, as ``numpy.random.default_rng`` takes) seeds a new one, and anything else
is one :class:`~optmodels.core.ProblemError` naming the argument. ``None`` (fresh entropy
from the operating system, not reproducible) is accepted only where the entry point says
so (``allow_none=True``: ``fusion.monte_carlo_weight``, the launcher scenarios); elsewhere
it is refused, so that a forgotten seed does not silently give an unrepeatable run.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optmodels import core

__all__ = ["as_generator"]


def as_generator(where: str, seed: Any, *, allow_none: bool = False) -> np.random.Generator:
    """A ``numpy.random.Generator`` from ``seed``.

    Parameters
    ----------
    where : str
        The argument's name in messages, e.g. ``"scenarios.climb_turn_track seed"``
        (:func:`optmodels.core.as_generator` appends `` seed`` to its own ``where``; this
        helper passes the name through unchanged).
    seed : numpy.random.Generator, int, sequence of int or None
        A Generator (returned as is), a whole number ≥ 0 or a sequence of them.
    allow_none : bool
        Whether ``None`` means a fresh, unseeded generator (default: refused).

    Returns
    -------
    numpy.random.Generator

    Raises
    ------
    ProblemError
        Naming ``where``, for a bool, float, string, negative number or ``None`` (unless
        allowed).
    """
    if seed is None and allow_none:
        return np.random.default_rng()
    return core.as_generator(where.removesuffix(" seed"), seed)
