"""Property-sweep recipes for the bias-field recording readers and the pipeline.

See :mod:`tests.sweep_support` for the vocabulary; merged into the sweep's RECIPES by
tests/test_property_sweep.py.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from tests.sweep_support import Ctx

R = dict[str, Callable[[Ctx], Any]]

RECIPES: dict[str, R] = {}

#: public entry points without a recipe yet, each with the reason
NOT_YET: dict[str, str] = {
    "biasfield.AircraftPaths": "needs simulated paths (tests/test_biasfield*.py)",
    "biasfield.CleaningLimits": "all arguments optional: swept by tests/test_cleaning*",
    "biasfield.absolute_error": "needs an ADS-B reference of a recording",
    "biasfield.adsb_field": "needs an ADS-B reference of a recording",
    "biasfield.adsb_reference": "needs ADS-B reports of a recording",
    "biasfield.azimuth_bias_baseline": "a long pipeline run",
    "biasfield.build_field_data": "a long pipeline run",
    "biasfield.clean_plots": "a long pipeline run",
    "biasfield.clean_reports": "needs ADS-B reports",
    "biasfield.compare_fields": "needs an ADS-B reference and fields",
    "biasfield.field_data_from_plots": "a long pipeline run",
    "biasfield.read_plots": "needs a plots file of a radar set",
    "biasfield.read_recording": "needs an ASTERIX recording",
    "biasfield.read_sites": "needs a sites CSV",
    "biasfield.read_tracks": "needs an ADS-B tracks CSV",
    "biasfield.residual_check": "needs track fits",
    "assignment.connected_probability": "an internal helper of soft marginals",
    "biasfield.adsb_height_spikes": "needs ADS-B reports (tests/test_cli_biasfield_out.py)",
    "biasfield.field_data_names": "needs an .npz written by `biasfield build`",
    "biasfield.save_field_data": "needs a FieldData of a pipeline run (test_biasfield_kill)",
}
