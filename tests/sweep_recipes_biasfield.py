"""Property-sweep recipes for the bias-field recording readers and the pipeline.

See :mod:`tests.sweep_support` for the vocabulary; merged into the sweep's RECIPES by
tests/test_property_sweep.py.

The good values come from one tiny simulated 3-D network (4 radars, 4 aircraft, 2 min:
165 plots) built once per session: its plots, radars, aircraft paths and ADS-B
positions in memory, and the files the readers take (a sites CSV keyed by SAC/SIC, a
plots CSV, an ADS-B tracks CSV, an ASTERIX recording of CAT048 + CAT021, a FieldData
``.npz``) written once into the session's folder. The pipeline steps run on it with 4
cells (a few tens of ms each): the smallest scene that still gives every answer (with 3
aircraft a radar has no ADS-B-referenced plot in the cells). Values that are not files
are built in memory, so that their types are known when the cases are collected (a
factory that needs a file raises there).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from optmodels import biasfield as bf
from tests.sweep_support import Ctx, Out, file_factory, make_file
from tests.test_cli_biasfield_build import write_sites

R = dict[str, Callable[[Ctx], Any]]

#: the common plane's origin of the network (lat deg, lon deg, h m)
ORG = (55.0, 83.0, 150.0)
#: cells of the pipeline runs: few (a Delaunay graph needs 3; a 4th keeps it a surface)
CELLS = 4


# ------------------------------------------------------------------ in memory
def _sc(c: Ctx) -> Any:
    """The 3-D network: 4 radars, 4 aircraft over 120 s (165 plots)."""
    from optmodels.scenarios.radar_network import radar_network

    return c.get(
        "bf3d", lambda: radar_network(1, n_aircraft=4, duration=120.0, geometry="3d", origin=ORG)
    )


def _plots(c: Ctx) -> bf.PlotTable:
    return _sc(c).plots  # type: ignore[no-any-return]


def _radars(c: Ctx) -> bf.RadarSet:
    return _sc(c).radars  # type: ignore[no-any-return]


def _build(c: Ctx) -> bf.FieldBuild:
    return c.get("bf3d-build", lambda: bf.field_data_from_plots(_plots(c), _radars(c), cells=CELLS))


def _fd(c: Ctx) -> bf.FieldData:
    return _build(c).data


def _ref(c: Ctx) -> np.ndarray:
    """ADS-B positions (n, 2) of the plots' aircraft (m, common plane)."""
    return c.get("bf3d-ref", lambda: _sc(c).adsb_positions(7))  # type: ignore[no-any-return]


def _map(c: Ctx) -> bf.FieldMap:
    """The smoothest field of the network's FieldData, as a map with its frame."""
    return c.get("bf3d-map", lambda: bf.field_map(bf.closed_form(_fd(c)), _fd(c)))


def _adsb(c: Ctx) -> bf.AdsbReports:
    """ADS-B reports of the aircraft (the true tracks; object = the plots' numbering),
    sorted by (object, time) as ``Recording.adsb``."""

    def make() -> bf.AdsbReports:
        paths = _sc(c).paths
        parts = [paths.track(a) for a in range(len(paths))]
        t = np.concatenate([p[0] for p in parts])
        geo = np.vstack([p[2] for p in parts])
        obj = np.concatenate([np.full(p[0].size, a) for a, p in enumerate(parts)])
        return bf.AdsbReports(
            t, obj, 0x3C0000 + obj, geo[:, 0], geo[:, 1], geo[:, 2], np.full(t.size, np.nan)
        )

    return c.get("bf3d-adsb", make)


def _keyed(c: Ctx) -> bf.RadarSet:
    """The radars keyed by SAC/SIC (25, 10 + i), as :func:`biasfield.read_sites` gives."""
    r = _radars(c)
    return c.get(
        "bf3d-keyed", lambda: dataclasses.replace(r, ids=tuple((25, 10 + i) for i in range(r.m)))
    )


def _enu(c: Ctx) -> np.ndarray:
    """The ADS-B reports' local ENU (n, 3) (m) about the origin: clean_reports' frame."""
    import pymap3d

    a = _adsb(c)
    return c.get(
        "bf3d-enu",
        lambda: np.column_stack(pymap3d.geodetic2enu(a.latitude, a.longitude, a.height, *ORG)),
    )


def _spiky(c: Ctx) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(object, time, height) of ADS-B reports with one height spike (+7.8 km)."""
    a = _adsb(c)
    h = a.height.copy()
    h[10] += 7800.0
    return a.object, a.time, h


def _u(c: Ctx) -> np.ndarray:
    """Pair probabilities (4, 4) of unresolved pairs (diagonal 1)."""
    u = np.eye(4)
    u[np.triu_indices(4, 1)] = [0.3, 0.05, 0.6, 0.2, 1e-3, 0.4]
    return np.maximum(u, u.T)


# ------------------------------------------------------------------ files
@file_factory()
def _sites_csv(c: Ctx) -> Any:
    r = _radars(c)
    assert r.geodetic is not None
    assert c.tmp is not None
    path = c.tmp / "bf-sites.csv"
    return path if path.exists() else write_sites(path, r)


@file_factory()
def _plots_csv(c: Ctx) -> Any:
    p, r = _plots(c), _radars(c)
    assert p.height is not None
    return make_file(
        c,
        "bf-plots.csv",
        "time,radar,range,azimuth,object,height\n"
        + "".join(
            f"{t!r},{r.names[k]},{g!r},{float(np.rad2deg(a))!r},A{o},{h!r}\n"
            for t, k, g, a, o, h in zip(
                p.time.tolist(),
                p.radar.tolist(),
                p.range.tolist(),
                p.azimuth,
                p.object.tolist(),
                p.height.tolist(),
                strict=True,
            )
        ),
    )


@file_factory()
def _tracks_csv(c: Ctx) -> Any:
    a = _adsb(c)
    return make_file(
        c,
        "bf-tracks.csv",
        "object,time,lat,lon,alt\n"
        + "".join(
            f"A{o},{t!r},{la!r},{lo!r},{h!r}\n"
            for o, t, la, lo, h in zip(
                a.object.tolist(),
                a.time.tolist(),
                a.latitude.tolist(),
                a.longitude.tolist(),
                a.height.tolist(),
                strict=True,
            )
        ),
    )


@file_factory()
def _recording(c: Ctx) -> Any:
    """The network as ASTERIX: CAT048 of every radar (SAC 25, SIC 10 + i), CAT021 of every
    aircraft (SAC 25, SIC 99), times of day from 30000 s."""
    from optmodels.io import encode_cat021, encode_cat048

    def data() -> bytes:
        p, r, a = _plots(c), _radars(c), _adsb(c)
        addr = 0x3C0000 + np.arange(len(_sc(c).paths))
        cat048 = b"".join(
            encode_cat048(
                p.time[p.radar == i] + 30000.0,
                25,
                10 + i,
                p.range[p.radar == i],
                p.azimuth[p.radar == i],
                address=addr[p.object[p.radar == i]],
            )
            for i in range(r.m)
        )
        cat021 = encode_cat021(
            a.time + 30000.0, 25, 99, a.latitude, a.longitude, height=a.height, address=a.address
        )
        return cat048 + cat021

    assert c.tmp is not None, "files are made when a test runs"
    return c.get("bf-recording", lambda: make_file(c, "bf-recording.ast", data()))


@file_factory()
def _fd_npz(c: Ctx) -> Any:
    assert c.tmp is not None, "files are made when a test runs"
    return c.get(
        "bf-fd-npz",
        lambda: bf.save_field_data(_fd(c), c.tmp / "bf-fd.npz", names=_radars(c).names),
    )


@file_factory(Out)
def _fd_out(c: Ctx) -> Out:
    return Out((c.tmp or Path("/tmp")) / "bf-out" / "fd.npz")


# ------------------------------------------------------------------ recipes
RECIPES: dict[str, R] = {
    "biasfield.AircraftPaths": {
        "times": lambda c: np.arange(5.0),
        "positions": lambda c: np.arange(20.0).reshape(2, 5, 2) * 1e3,
        "active": lambda c: np.array([[True] * 5, [False, True, True, True, False]]),
    },
    # every argument optional: each swept (ground_ceiling's default None: speed alone)
    "biasfield.CleaningLimits": {
        "max_speed": lambda c: 350.0,
        "max_acceleration": lambda c: 29.4,
        "ground_speed": lambda c: 40.0,
        "ground_window": lambda c: 30.0,
        "ground_ceiling": lambda c: 500.0,
        "max_gap": lambda c: 10.0,
        "min_points": lambda c: 2,
        "glitch_run": lambda c: 3,
        "noise_sigmas": lambda c: 6.0,
    },
    "biasfield.clean_plots": {
        "plots": _plots,
        "radars": _radars,
        "limits": lambda c: bf.CleaningLimits(max_gap=60.0, min_points=1, ground_window=60.0),
    },
    "biasfield.clean_reports": {
        "objects": lambda c: _adsb(c).object,
        "times": lambda c: _adsb(c).time,
        "positions": _enu,
        "sigma": lambda c: 10.0,
        "heights": lambda c: _adsb(c).height,
        "limits": lambda c: bf.CleaningLimits(ground_ceiling=500.0),
    },
    "biasfield.adsb_height_spikes": {
        "obj": lambda c: _spiky(c)[0],
        "t": lambda c: _spiky(c)[1],
        "height": lambda c: _spiky(c)[2],
        "neighbours": lambda c: 2,
        "tolerance": lambda c: 150.0,
        "vertical_rate": lambda c: 100.0,
    },
    # ---------------------------------------------------------------- readers
    "biasfield.read_sites": {"path": _sites_csv, "origin": lambda c: ORG},
    # not swept: ``labels`` (an output list the labels are written into: any list, a
    # ragged one too, is good; a non-list is refused, tests/test_biasfield_sweep_findings.py)
    "biasfield.read_plots": {
        "path": _plots_csv,
        "radars": _radars,
        "azimuth_unit": lambda c: "deg",
        "drop_out_of_range": lambda c: True,
    },
    "biasfield.read_tracks": {
        "path": _tracks_csv,
        "origin": lambda c: ORG,
        "step": lambda c: 2.0,
        "clean": lambda c: True,
        "limits": lambda c: bf.CleaningLimits(),
        "sigma": lambda c: 10.0,
        "report": lambda c: True,
    },
    "biasfield.read_recording": {
        "paths": _recording,
        "radars": _keyed,
        "origin": lambda c: ORG,
        "date": lambda c: "2024-05-01",
        "max_gap": lambda c: 20.0,
        "geoid_undulation": lambda c: 40.0,
        "drop_out_of_range": lambda c: True,
        "editions": lambda c: {48: (1, 32), 21: (2, 7)},
        "height_margin": lambda c: 300.0,
        "height_margin_rel": lambda c: 0.08,
        "clean_heights": lambda c: True,
    },
    # ---------------------------------------------------------------- pipeline
    "biasfield.field_data_from_plots": {
        "plots": _plots,
        "radars": _radars,
        "cells": lambda c: CELLS,
        "knot_spacing": lambda c: 20.0,
        "coverage": lambda c: "union",
        "clean": lambda c: False,
        "locate": lambda c: True,
        "scheduler": lambda c: "serial",
        "progress": lambda c: False,
        "seed": lambda c: 0,
    },
    # the Delaunay neighbours ignore neighbour_radius (checked whenever it is given): the
    # radius neighbours, so that both are used
    "biasfield.build_field_data": {
        "plots": _plots,
        "radars": _radars,
        "cells": lambda c: CELLS,
        "cell_radius": lambda c: 60e3,
        "knot_spacing": lambda c: 20.0,
        "sample_step": lambda c: 5.0,
        "neighbour_method": lambda c: "radius",
        "neighbour_radius": lambda c: 200e3,
        "P": lambda c: _fd(c).P,
        "exclude_radius": lambda c: 20e3,
        "seed": lambda c: 0,
        "scheduler": lambda c: "serial",
        "positions": lambda c: _plots(c).cartesian(_radars(c)),
        "coverage": lambda c: "all",
        "subset_share": lambda c: 0.5,
        "progress": lambda c: False,
    },
    "biasfield.azimuth_bias_baseline": {
        "plots": _plots,
        "radars": _radars,
        "objects": lambda c: [0, 1, 2, 3],
        "knot_spacing": lambda c: 20.0,
        "max_gap": lambda c: 30.0,
    },
    "biasfield.residual_check": {
        "fits": lambda c: _build(c).diagnostics.fits,
        "m": lambda c: _radars(c).m,
    },
    # not swept: ``name`` (the label of ``path`` in messages, e.g. the CLI's "--out")
    "biasfield.save_field_data": {
        "data": _fd,
        "path": _fd_out,
        "names": lambda c: _radars(c).names,
    },
    "biasfield.field_data_names": {"path": _fd_npz},
    # ---------------------------------------------------------------- ADS-B referee
    "biasfield.adsb_reference": {
        "plots": _plots,
        "adsb": _adsb,
        "origin": lambda c: ORG,
        "max_gap": lambda c: 10.0,
    },
    "biasfield.adsb_field": {
        "data": _fd,
        "plots": _plots,
        "radars": _radars,
        "reference": _ref,
        "cell_radius": lambda c: 60e3,
        "sigma_reference": lambda c: 10.0,
        "model": lambda c: "cells",
        "level": lambda c: "discrepancy",
    },
    "biasfield.absolute_error": {
        "plots": _plots,
        "radars": _radars,
        "reference": _ref,
        "area": lambda c: 25e3,
        "min_samples": lambda c: 20,
        "within": _map,
        "positions": lambda c: _plots(c).cartesian(_radars(c)),
    },
    "biasfield.compare_fields": {
        "plots": _plots,
        "radars": _radars,
        "reference": _ref,
        "fields": lambda c: {"smoothest": _map(c)},
        "area": lambda c: 25e3,
    },
    # ---------------------------------------------------------------- assignment
    # not swept: ``memo`` (a cache dict kept between calls: any dict is good)
    "assignment.connected_probability": {"u": _u, "group": lambda c: (0, 1, 2, 3)},
}

#: public entry points without a recipe yet, each with the reason
NOT_YET: dict[str, str] = {}
