"""Radar bias fields (paper 001, Bedin): from radar plots to uncertainty sets (part 1),
and the smoothest field on them (part 2).

Paper: ``shared/papers/001_d6b2428a10e192f8.txt``. Errata: ``docs/errata.md``.

The modules in the order the data travels (tests/test_biasfield_rooms.py holds the order):

* inputs: ``tables`` (:class:`RadarSet`, :class:`PlotTable`), ``paths``
  (:class:`AircraftPaths`), ``geometry`` (polar maps), ``geometry3d`` (the exact 3-D
  geometry: slant range, each radar's own north, the common plane), ``fields`` (bias field
  models), ``ingest`` (files), ``heights`` (flight level → height, ADS-B height spikes),
  ``recording`` (ASTERIX CAT048 / CAT021 in), ``frames`` (pandas in and out),
  ``cleaning`` (gaps, glitches, ground traffic);
* tracks: ``polyline`` (the polyline's basis, knots and band solves), ``tracks`` (the track
  fits (3)), ``baseline`` (the parametric baseline (2)-(4));
* field data: ``cells`` (:func:`build_field_data`: cells, averaging (6)-(7)), ``averaging``
  (its helpers), ``data`` (:class:`FieldData`, neighbours, the uncertainty sets (10)),
  ``pipeline`` (plots → FieldData in one call);
* selection (section 4), in the one skeleton of the problem packages: ``problem`` (the
  original problem (8)-(10): objective (9), R, the box, the shared argument checks),
  ``solution`` (:class:`FieldSolution` and its failure form), ``verify`` (the NumPy
  re-checks, identifiability and the gate), ``closedform`` (closed form (11)), ``generic``
  (the QP (9)-(10) [+ (8)] and the Lipschitz SOCP);
* use (issue 17): ``usage`` (:class:`FieldMap`, :func:`correct_plots`,
  :func:`registration_error`, :func:`score`), ``referee`` (ADS-B as the referee).
"""

from optmodels.biasfield import geometry3d
from optmodels.biasfield.baseline import BaselineResult, azimuth_bias_baseline
from optmodels.biasfield.cells import build_field_data, place_centers
from optmodels.biasfield.cleaning import (
    CleaningLimits,
    CleaningReport,
    clean_plots,
    clean_reports,
)
from optmodels.biasfield.closedform import closed_form
from optmodels.biasfield.data import (
    FieldData,
    laplacian,
    neighbours,
    synthetic_field_data,
    uncertainty_sets,
)
from optmodels.biasfield.fields import BiasField
from optmodels.biasfield.frames import from_frame, to_frame
from optmodels.biasfield.generic import solve, solve_lipschitz
from optmodels.biasfield.geometry import (
    bias_from_shift,
    from_polar,
    polar_jacobian,
    shift_from_bias,
    to_polar,
    wrap_angle,
)
from optmodels.biasfield.heights import adsb_height_spikes, fl_to_height
from optmodels.biasfield.ingest import read_plots, read_radars, read_tracks
from optmodels.biasfield.paths import AircraftPaths
from optmodels.biasfield.pipeline import (
    FieldBuild,
    field_data_from_plots,
    field_data_names,
    save_field_data,
)
from optmodels.biasfield.polyline import hat_basis
from optmodels.biasfield.recording import (
    AdsbReports,
    Recording,
    RecordingReport,
    read_recording,
    read_sites,
)
from optmodels.biasfield.referee import (
    AbsoluteError,
    AdsbField,
    absolute_error,
    adsb_field,
    adsb_reference,
    compare_fields,
)
from optmodels.biasfield.solution import FieldSolution
from optmodels.biasfield.summary import radar_baseline
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.biasfield.tracks import ResidualCheck, TrackFit, fit_tracks, residual_check
from optmodels.biasfield.usage import (
    Corrected,
    FieldMap,
    FieldScore,
    RegistrationError,
    correct_plots,
    field_map,
    registration_error,
    score,
    seen_by_others,
)

__all__ = [
    "AbsoluteError",
    "AdsbField",
    "AdsbReports",
    "AircraftPaths",
    "BaselineResult",
    "BiasField",
    "CleaningLimits",
    "CleaningReport",
    "Corrected",
    "FieldBuild",
    "FieldData",
    "FieldMap",
    "FieldScore",
    "FieldSolution",
    "PlotTable",
    "RadarSet",
    "Recording",
    "RecordingReport",
    "RegistrationError",
    "ResidualCheck",
    "TrackFit",
    "absolute_error",
    "adsb_field",
    "adsb_height_spikes",
    "adsb_reference",
    "azimuth_bias_baseline",
    "bias_from_shift",
    "build_field_data",
    "clean_plots",
    "clean_reports",
    "closed_form",
    "compare_fields",
    "correct_plots",
    "field_data_from_plots",
    "field_data_names",
    "field_map",
    "fit_tracks",
    "fl_to_height",
    "from_frame",
    "from_polar",
    "geometry3d",
    "hat_basis",
    "laplacian",
    "neighbours",
    "place_centers",
    "polar_jacobian",
    "radar_baseline",
    "read_plots",
    "read_radars",
    "read_recording",
    "read_sites",
    "read_tracks",
    "registration_error",
    "residual_check",
    "save_field_data",
    "score",
    "seen_by_others",
    "shift_from_bias",
    "solve",
    "solve_lipschitz",
    "synthetic_field_data",
    "to_frame",
    "to_polar",
    "uncertainty_sets",
    "wrap_angle",
]
