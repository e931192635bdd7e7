"""Plane of maneuver (paper 000): :class:`PlaneAngle`, the angle error of the ML plane
(reduced NLP, or the closed form when D_i = α_i² D) and of the SVD plane, against the
Cramér–Rao bound of the angle.

The study imports :mod:`optmodels.plane` (and :mod:`optmodels.scenarios`) inside the
trial, so that a worker process loads only what it runs; it is found by
:data:`optmodels.montecarlo.studies.STUDIES` through this module's name (the problem's).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from optmodels.core import ProblemError, as_count
from optmodels.montecarlo.studies._common import _set

__all__ = ["PlaneAngle"]


@dataclass(frozen=True)
class PlaneAngle:
    """Plane of maneuver (paper 000): angle error (rad) of the ML plane and of the
    unweighted SVD plane, and the Cramér–Rao bound of the angle for the trial's truth.
    ``setting``: "two-source" (D_i = α_i² D, closed form) or "radar" (general D_i,
    reduced NLP)."""

    name: ClassVar[str] = "plane-angle"
    problem: ClassVar[str] = "plane"
    #: The unit of each per-trial value and summary entry (``optmodels montecarlo`` prints it).
    units: ClassVar[dict[str, str]] = {
        "ml": "rad (angle between the ML and the true normal)",
        "svd": "rad (angle between the SVD and the true normal)",
        "crb2": "rad² (Cramér–Rao bound of the angle, squared)",
        "rmse_ml": "rad",
        "rmse_svd": "rad",
        "crb": "rad (RMS Cramér–Rao bound of the angle)",
        "ml_over_crb": "ratio (1: the bound is reached)",
    }

    n: int = 50
    setting: str = "radar"

    def __post_init__(self) -> None:
        _set(self, "n", as_count("montecarlo.PlaneAngle n", self.n, minimum=3))
        if self.setting not in ("radar", "two-source"):
            raise ProblemError(
                f"montecarlo.PlaneAngle setting: expected 'radar' or "
                f"'two-source', got {self.setting!r}"
            )

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import plane, scenarios

        sc = (
            scenarios.two_source_plane(self.n, rng)
            if self.setting == "two-source"
            else scenarios.radar_plane(self.n, rng, geometry="broadside")
        )
        data = plane.PlaneData(sc.points, sc.cov, sc.alpha2)
        ml = (
            plane.closed_form(data) if data.proportional else plane.solve(data, "reduced")
        ).require_ok()
        crb = plane.cramer_rao_bound(
            plane.PlaneData(sc.truth, sc.cov, sc.alpha2), sc.normal, sc.offset
        )
        return {
            "ml": float(plane.angle_error(ml.normal, sc.normal)),
            "svd": float(plane.angle_error(plane.svd_fit(data).normal, sc.normal)),
            "crb2": float(crb.angle_rms**2),
        }

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        crb = float(np.sqrt(np.mean(v["crb2"])))
        return {
            "rmse_ml": float(np.sqrt(np.mean(v["ml"] ** 2))),
            "rmse_svd": float(np.sqrt(np.mean(v["svd"] ** 2))),
            "crb": crb,
            "ml_over_crb": float(np.sqrt(np.mean(v["ml"] ** 2))) / crb,
        }
