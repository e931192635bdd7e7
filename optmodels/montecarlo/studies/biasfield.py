"""Bias field (paper 001): :class:`BiasfieldRecovery`, the RMS error (range, azimuth) of
the closed-form smoothest field (11) against the true smooth field.

The study imports :mod:`optmodels.biasfield` inside the trial, so that a worker process
loads only what it runs; it is found by :data:`optmodels.montecarlo.studies.STUDIES`
through this module's name (the problem's).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from optmodels.core import as_count, as_positive
from optmodels.montecarlo.studies._common import _set

__all__ = ["BiasfieldRecovery"]


@dataclass(frozen=True)
class BiasfieldRecovery:
    """Bias field (paper 001): RMS error of the closed-form smoothest field (11) against
    the true smooth field, range (m) and azimuth (mrad), on synthetic uncertainty sets with
    ``noise`` metres of position noise."""

    name: ClassVar[str] = "biasfield-recovery"
    problem: ClassVar[str] = "biasfield"
    #: The unit of each per-trial value and summary entry (``optmodels montecarlo`` prints it).
    units: ClassVar[dict[str, str]] = {
        "range_rms_m": "m",
        "azimuth_rms_mrad": "mrad",
    }

    cells: int = 200
    noise: float = 20.0

    def __post_init__(self) -> None:
        _set(self, "cells", as_count("montecarlo.BiasfieldRecovery cells", self.cells, minimum=3))
        _set(
            self,
            "noise",
            as_positive("montecarlo.BiasfieldRecovery noise", self.noise, allow_zero=True),
        )

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import biasfield as bf

        data, truth = bf.synthetic_field_data(rng, cells=self.cells, noise=self.noise)
        f = bf.closed_form(data).require_ok().field
        err = f - truth
        return {
            "range_rms_m": float(np.sqrt(np.mean(err[..., 0] ** 2))),
            "azimuth_rms_mrad": float(np.sqrt(np.mean(err[..., 1] ** 2)) * 1e3),
        }
