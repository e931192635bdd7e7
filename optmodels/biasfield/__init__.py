"""Radar bias fields (paper 001, Bedin): from radar plots to uncertainty sets (part 1),
and the smoothest field on them (part 2).

Paper: ``shared/papers/001_d6b2428a10e192f8.txt``. Errata: ``docs/errata.md``.

Part 1: ``data`` (plot tables, radar sites), ``geometry`` (polar maps), ``ingest`` (files),
``tracks`` (track fits), ``baseline``, ``cells`` (cells and the uncertainty sets (10)),
``fields`` (bias field models). Part 2 (section 4; entry point ``selection``): ``problem``
(the original problem (8)-(10), :class:`FieldSolution`), ``selection`` (closed form (11),
the QP (9)-(10)), ``lipschitz`` (the Lipschitz class), ``verify`` (the NumPy re-checks),
``identifiability``.
"""

from optmodels.biasfield.baseline import BaselineResult, azimuth_bias_baseline
from optmodels.biasfield.cells import (
    FieldData,
    build_field_data,
    laplacian,
    neighbours,
    place_centers,
    synthetic_field_data,
    uncertainty_sets,
)
from optmodels.biasfield.data import PlotTable, RadarSet
from optmodels.biasfield.fields import BiasField
from optmodels.biasfield.geometry import (
    bias_from_shift,
    from_polar,
    polar_jacobian,
    shift_from_bias,
    to_polar,
    wrap_angle,
)
from optmodels.biasfield.ingest import read_plots, read_radars, read_tracks
from optmodels.biasfield.lipschitz import solve_lipschitz
from optmodels.biasfield.problem import FieldSolution
from optmodels.biasfield.selection import closed_form, solve
from optmodels.biasfield.tracks import (
    ResidualCheck,
    TrackFit,
    fit_tracks,
    hat_basis,
    residual_check,
)

__all__ = [
    "BaselineResult",
    "BiasField",
    "FieldData",
    "FieldSolution",
    "PlotTable",
    "RadarSet",
    "ResidualCheck",
    "TrackFit",
    "azimuth_bias_baseline",
    "bias_from_shift",
    "build_field_data",
    "closed_form",
    "fit_tracks",
    "from_polar",
    "hat_basis",
    "laplacian",
    "neighbours",
    "place_centers",
    "polar_jacobian",
    "read_plots",
    "read_radars",
    "read_tracks",
    "residual_check",
    "shift_from_bias",
    "solve",
    "solve_lipschitz",
    "synthetic_field_data",
    "to_polar",
    "uncertainty_sets",
    "wrap_angle",
]
