r"""The plane's solution and its failure form (paper 000 (1.1), (1.8)).

:class:`PlaneSolution` is what every estimator of the package returns (the generic
:func:`optmodels.plane.solve`, :func:`optmodels.plane.closed_form`,
:meth:`~optmodels.plane.general.GeneralFit.to_solution`); :func:`_failure` is the form of a
result the gate refused (:func:`optmodels.plane.verify._finish`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optmodels.core import FloatArray, Solution

__all__ = ["PlaneSolution"]


@dataclass
class PlaneSolution(Solution):
    """A plane estimate with the projected points.

    Attributes
    ----------
    normal : ndarray (3,)
        Unit normal ``n``; sign convention: ``offset >= 0``, and if ``offset == 0`` the
        first non-zero component of ``normal`` is positive.
    offset : float
        ``a`` in :math:`\\langle n, x\\rangle = a` (1.1).
    projected : ndarray (N, 3)
        The estimated positions :math:`x_i` on the plane (1.8).
    resolved : bool or None
        Whether the data determine the plane: the hypothesis "the points are on a line"
        is rejected at the fit's ``level`` (:func:`optmodels.plane.general.line_test`;
        ``info["line_test"]`` holds its numbers). ``False``: the fit is not OK (status
        ERROR, message "unresolved: ..."), ``normal``/``offset`` are NaN (every plane
        through the line fits about as well) and ``line_direction`` is what the data
        determine. ``None``: not tested (the fit failed first, or ``level=None``).
    line_direction : ndarray (3,)
        Unit direction of the maximum-likelihood line (NaN where not tested).
    """

    normal: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    offset: float = float("nan")
    projected: FloatArray = field(default_factory=lambda: np.empty((0, 3)))
    resolved: bool | None = None
    line_direction: FloatArray = field(default_factory=lambda: np.full(3, np.nan))


def _failure(sol: PlaneSolution) -> PlaneSolution:
    """The failure form of a plane solution: NaN normal and offset, no projected points;
    what the solver returned is kept in ``info["rejected"]``."""
    sol.info["rejected"] = {"normal": sol.normal, "offset": sol.offset}
    sol.normal = np.full(3, np.nan)
    sol.offset = float("nan")
    sol.projected = np.empty((0, 3))
    return sol
