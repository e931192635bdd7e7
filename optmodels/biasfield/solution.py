r"""The bias field's solution and its failure form (paper 001, section 4, (8)-(11)).

:class:`FieldSolution` is what every method of the selection stage returns (the closed form
(11) :func:`optmodels.biasfield.closed_form`, the QP (9)-(10) [+ (8)]
:func:`optmodels.biasfield.solve`, the Lipschitz SOCP
:func:`optmodels.biasfield.solve_lipschitz`); :func:`_failure` is the form of a result the
gate refused (:func:`optmodels.biasfield.verify._finish`): no field.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import FloatArray, ProblemError, Solution

if TYPE_CHECKING:  # usage imports the selection stage; at run time FieldMap is imported lazily
    from optmodels.biasfield.usage import FieldMap

__all__ = ["FieldSolution"]


@dataclass
class FieldSolution(Solution):
    """A field on the cells: ``field`` (K, m, 2) = [range, azimuth] bias per cell and radar,
    ``phi`` (2mK,), ``eta`` (K, 2); ``active`` (K, m, 2) box constraints at their bound
    (+1 upper, −1 lower, 0 free); ``duals`` (K, m, 2) their multipliers (≥ 0, signed like
    ``active``); ``lipschitz`` L for :func:`~optmodels.biasfield.generic.solve_lipschitz`.

    ``centers`` (K, 2) the cell centres x̌_k (m, common plane) the field belongs to, and
    ``frame`` the data's frame (``sites`` (m, 2); ``geodetic`` (m, 3) and ``origin`` (3,)
    for the exact 3-D chain; None where absent); ``seen`` (K, m) the radars of each cell
    (per-cell subsets; ``field`` is 0 where a radar does not see a cell, and the map serves
    each radar over its own cells only): with them :meth:`at` evaluates the field
    anywhere in the covered area and :meth:`map` gives the
    :class:`~optmodels.biasfield.usage.FieldMap` to correct plots with or to save."""

    field: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    phi: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    eta: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    active: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0))
    duals: FloatArray = dataclasses.field(default_factory=lambda: np.empty(0))
    lipschitz: float | None = None
    centers: FloatArray = dataclasses.field(default_factory=lambda: np.empty((0, 2)))
    frame: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False)
    seen: np.ndarray | None = None

    def map(self, *, names: Sequence[str] = (), max_distance: float | None = None) -> FieldMap:
        """The field as a :class:`~optmodels.biasfield.usage.FieldMap` (the P1 interpolant
        on the Delaunay triangulation of ``centers``, with the data's frame and the radars'
        ``names`` if given; ``max_distance`` (m) bounds the covered area, default 1.5 × the
        largest nearest-neighbour distance of the centres). Refused (ProblemError) for a
        solution with no field (status not OK) or without its cells."""
        from optmodels.biasfield.usage import FieldMap

        if not self.status.ok:
            raise ProblemError(
                f"biasfield.FieldSolution.map: status {self.status.value} has no field to use"
            )
        c = np.asarray(self.centers, dtype=float)
        if c.ndim != 2 or c.shape[0] != np.shape(self.field)[0]:
            raise ProblemError(
                "biasfield.FieldSolution.map: the solution carries no cell "
                f"centres for its field (centers {c.shape}, field "
                f"{np.shape(self.field)}); use biasfield.field_map(solution, "
                "data)"
            )
        key = (tuple(str(n) for n in names), max_distance)
        cache = self.__dict__.get("_maps")
        if cache is None or cache[0] != key or cache[2] is not self.field:
            dmax = float("nan") if max_distance is None else max_distance
            fm = FieldMap(
                c,
                self.field,
                dmax,
                key[0],
                self.frame.get("sites"),
                self.frame.get("geodetic"),
                self.frame.get("origin"),
                self.frame.get("chain", ""),
                seen=self.seen,
            )
            cache = (key, fm, self.field)
            self.__dict__["_maps"] = cache
        fm_cached: FieldMap = cache[1]
        return fm_cached

    def __getstate__(self) -> dict[str, Any]:  # the cached interpolant is not pickled
        state = dict(self.__dict__)
        state.pop("_maps", None)
        return state

    def at(self, points: ArrayLike) -> FloatArray:
        """The estimated field at ``points`` (n, 2) (m, East/North on the common plane):
        (n, m, 2) = [range bias (m), azimuth bias (rad)] per radar. Exactly the cell
        values at the centres; between them the P1 interpolant of :meth:`map`
        (docs/formulations.md: consistent with the smoothness functional (9)); NaN outside
        the covered area (:meth:`covered`)."""
        return self.map().at(points)

    def covered(self, points: ArrayLike) -> np.ndarray:
        """(n,) True where :meth:`at` is defined (inside the triangulation of the centres
        and near one)."""
        return self.map().covered(points)

    @property
    def max_residual(self) -> float:
        """Largest KKT/feasibility residual; ``residuals["dual_sign"]`` (the share of
        box multipliers with a sign off, a diagnostic) is not a residual and is left out."""
        vals = [float(v) for k, v in self.residuals.items() if k != "dual_sign"]
        if any(np.isnan(v) for v in vals):
            return float("nan")
        return max(vals, default=0.0)


def _failure(sol: FieldSolution) -> FieldSolution:
    """The bias field's failure form: no field, φ, η (NaN), no Lipschitz constant (NaN
    where one was computed); the residuals and ``info`` stay for diagnosis."""
    sol.field = np.full_like(sol.field, np.nan)
    sol.phi = np.full_like(sol.phi, np.nan)
    sol.eta = np.full_like(sol.eta, np.nan)
    sol.lipschitz = None if sol.lipschitz is None else float("nan")
    return sol
