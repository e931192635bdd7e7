"""Property-based sweep over the whole public API (issue 28 item 5).

The entry points are **discovered**, not listed: every name in the ``__all__`` of each
problem package the registry knows (:func:`optmodels.registry.problems`) and of
:mod:`optmodels.io`. Each is classified by a rule:

* a constant (not callable), or a record type (a dataclass without validation: the
  package builds it, e.g. a ``Solution``): nothing to sweep;
* a callable without parameters: called (the good path only);
* every other callable needs a recipe in :data:`RECIPES` (its good arguments); the test
  :func:`test_every_public_entry_point_is_swept` fails when a public name has neither a
  recipe nor a rule, so a new entry point cannot slip past the sweep.

For every argument of a recipe, hypothesis generates **bad values** of the kinds that fit
the good value's type (ragged nested lists, text arrays, ``None`` entries, complex
numbers, mappings, NaN scalars, unknown choices, wrong types, missing files): each must give
one :class:`~optmodels.core.ProblemError` whose message names the argument -- never a raw
exception, never silent acceptance. The **good values** must give an answer; a
:class:`~optmodels.core.Solution` with an OK status must pass the re-check of
``tests.conftest.assert_verified`` (OK implies verified), and perturbed good values
(positive rescaling of the numeric arrays) must give a verified answer or an optmodels
refusal.

Bounded in CI (a few examples per case); ``OPTMODELS_SWEEP=full`` (or the ``slow`` twin,
run by ``make test-all``) runs many more. Known defects in files outside this sweep's
owner are ``xfail(strict=True)`` with the reason (:data:`KNOWN`), so they turn the run red
the day they are fixed and the mark is stale.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st

from optmodels import assignment as asg
from optmodels import biasfield as bf
from optmodels import fusion as fu
from optmodels import io, plane, registry
from optmodels import trajectories as tr
from optmodels.core import OptModelsError, ProblemError, Solution, SolverNotAvailable
from tests import sweep_recipes_biasfield, sweep_recipes_io
from tests.conftest import assert_verified
from tests.sweep_support import (
    FILE_FACTORIES,
    FOREIGN_PREFIX,
    AnyFile,
    Anything,
    BadFile,
    Ctx,
    Free,
    Out,
    TextFile,
    file_factory,
    make_file,
)

FULL = os.environ.get("OPTMODELS_SWEEP", "") == "full"
#: examples per (entry point, argument): CI / full (``OPTMODELS_SWEEP=full``, ``slow``)
N_CI, N_FULL = 6, 40


# ------------------------------------------------------------------ discovery
def public_entries() -> dict[str, Any]:
    """``package.name`` -> object, for every name in the ``__all__`` of every registered
    problem package and of :mod:`optmodels.io`."""
    out: dict[str, Any] = {}
    for prob in registry.problems():
        mod = prob.module()
        for name in mod.__all__:
            out[f"{prob.name}.{name}"] = getattr(mod, name)
    for name in io.__all__:
        out[f"io.{name}"] = getattr(io, name)
    return out


def _generated_init(cls: type) -> bool:
    """The class's ``__init__`` is the one :mod:`dataclasses` wrote (no checks in it)."""
    code = getattr(getattr(cls, "__init__", None), "__code__", None)
    return code is not None and code.co_filename.startswith("<")


def rule(obj: Any) -> str | None:
    """Why an entry needs no recipe (None: it needs one)."""
    if not callable(obj):
        return "constant"
    if (
        inspect.isclass(obj)
        and dataclasses.is_dataclass(obj)
        and not hasattr(obj, "__post_init__")
        and _generated_init(obj)
    ):
        return "record type (no validation; built by the package)"
    if inspect.isclass(obj) and issubclass(obj, tuple) and hasattr(obj, "_fields"):
        return "record type (a named tuple)"
    if inspect.isclass(obj) and issubclass(obj, Solution):
        return "record type (a Solution)"
    try:
        params = inspect.signature(obj).parameters
    except (TypeError, ValueError):
        return "no signature"
    if not [p for p in params.values() if p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)]:
        return "no arguments (called once)"
    return None


# ------------------------------------------------------------------ good values
def _arc(n: int = 30) -> np.ndarray:
    rng = np.random.default_rng(20261202)
    ang = np.linspace(0, 3, n)
    return np.c_[np.cos(ang), np.sin(ang), np.zeros(n)] * 1e3 + rng.normal(scale=5.0, size=(n, 3))


def _pd(c: Ctx) -> plane.PlaneData:
    return c.get("pd", lambda: plane.PlaneData(_arc(), 25.0 * np.eye(3)))


def _pcf(c: Ctx) -> plane.PlaneSolution:
    return c.get("pcf", lambda: plane.closed_form(_pd(c)))


_T = [np.arange(10.0), np.arange(12.0)]


def _td(c: Ctx) -> tr.TrajectoryData:
    rng = np.random.default_rng(5)
    return c.get(
        "td",
        lambda: tr.TrajectoryData(
            _T, [2.0 * _T[0] + 1.0 + rng.normal(size=10), -_T[1] + 1.0 + rng.normal(size=12)], 1.0
        ),
    )


def _tcf(c: Ctx) -> tr.TrajectorySolution:
    return c.get("tcf", lambda: tr.closed_form(_td(c)))


_S1 = np.array([[2.0, 0.3], [0.3, 1.0]])
_S2 = np.array([[1.0, -0.2], [-0.2, 3.0]])


def _fd(c: Ctx) -> bf.FieldData:
    return c.get("fd", lambda: bf.synthetic_field_data(0, cells=12)[0])


def _fsol(c: Ctx) -> bf.FieldSolution:
    return c.get("fsol", lambda: bf.closed_form(_fd(c)))


def _fmap(c: Ctx) -> bf.FieldMap:
    return c.get("fmap", lambda: bf.field_map(_fsol(c), _fd(c)))


def _net(c: Ctx) -> Any:
    from optmodels.scenarios import radar_network

    return c.get("net", lambda: radar_network(1, n_aircraft=4, duration=240.0))


def _ad(c: Ctx) -> asg.AssignmentData:
    return c.get(
        "ad",
        lambda: asg.AssignmentData(
            np.array([[0.0, 0.0], [10.0, 0.0]]),
            np.stack([np.eye(2)] * 2),
            np.array([[0.1, -0.2], [9.8, 0.3], [5.0, 5.0]]),
            np.eye(2),
            400.0,
            0.9,
            0.2,
        ),
    )


def _file(c: Ctx, name: str, text: str) -> Path:
    return make_file(c, name, text)


def _plane_csv(c: Ctx) -> Path:
    pts = _arc(8)
    return _file(
        c,
        "plane.csv",
        "t,x,y,z\n"
        + "".join(f"{i},{a:.17g},{b:.17g},{d:.17g}\n" for i, (a, b, d) in enumerate(pts)),
    )


@file_factory(AnyFile)
def _any_file(c: Ctx) -> AnyFile:
    """A path only checked for being a readable file (its content is not judged)."""
    return AnyFile(_plane_csv(c))


@file_factory(TextFile)
def _text_file(c: Ctx) -> TextFile:
    """A text file whose content is not judged beyond being text."""
    return TextFile(_plane_csv(c))


def _traj_csv(c: Ctx) -> Path:
    return _file(
        c,
        "traj.csv",
        "object,t,y\n"
        + "".join(
            f"{j},{t},{2.0 * t + j + 0.1 * ((-1) ** int(t))}\n" for j in range(2) for t in range(6)
        ),
    )


def _radars_csv(c: Ctx) -> Path:
    return _file(
        c,
        "radars.csv",
        "name,x,y,sigma_range,sigma_azimuth,max_range\n"
        "A,0,0,50,0.08,300000\nB,40000,0,50,0.08,300000\nC,0,40000,50,0.08,300000\n",
    )


#: entry point -> {argument: good value factory (Ctx -> value)}. The arguments listed are
#: the ones swept (required ones must be listed; optional ones are swept when listed).
R = dict[str, Callable[[Ctx], Any]]
RECIPES: dict[str, R] = {
    # ---------------------------------------------------------------- plane
    "plane.PlaneData": {"points": lambda c: _arc(), "cov": lambda c: 25.0 * np.eye(3)},
    "plane.closed_form": {"data": _pd, "level": lambda c: 0.99},
    "plane.svd_fit": {"data": _pd},
    "plane.solve": {"data": _pd, "formulation": lambda c: "reduced", "starts": lambda c: 1},
    "plane.planarity_test": {"data": _pd, "solution": _pcf, "level": lambda c: 0.99},
    "plane.line_test": {"data": _pd, "level": lambda c: 0.99},
    "plane.objective": {"data": _pd, "projected": lambda c: _pcf(c).projected},
    "plane.constraint_residuals": {
        "data": _pd,
        "projected": lambda c: _pcf(c).projected,
        "normal": lambda c: _pcf(c).normal,
        "offset": lambda c: _pcf(c).offset,
    },
    "plane.cramer_rao_bound": {
        "data": _pd,
        "normal": lambda c: _pcf(c).normal,
        "offset": lambda c: _pcf(c).offset,
    },
    "plane.optimal_offset": {"data": _pd, "normal": lambda c: _pcf(c).normal},
    "plane.project": {
        "data": _pd,
        "normal": lambda c: _pcf(c).normal,
        "offset": lambda c: _pcf(c).offset,
    },
    "plane.reduced_objective": {
        "data": _pd,
        "normal": lambda c: _pcf(c).normal,
        "offset": lambda c: _pcf(c).offset,
    },
    "plane.angle_error": {
        "normal": lambda c: _pcf(c).normal,
        "true_normal": lambda c: np.array([0.0, 0.0, 1.0]),
    },
    "plane.plane_errors": {
        "normal": lambda c: _pcf(c).normal,
        "offset": lambda c: _pcf(c).offset,
        "true_normal": lambda c: np.array([0.0, 0.0, 1.0]),
        "true_offset": lambda c: 0.0,
    },
    "plane.fit_general": {
        "points": lambda c: _arc(),
        "cov": lambda c: np.stack([25.0 * np.eye(3)] * 30),
        "level": lambda c: 0.99,
    },
    "plane.identify_sequence": {
        "times": lambda c: np.arange(30.0),
        "points": lambda c: _arc(),
        "cov": lambda c: 25.0 * np.eye(3),
        "level": lambda c: 0.99,
    },
    "plane.track": {
        "times": lambda c: np.arange(30.0),
        "points": lambda c: _arc(),
        "cov": lambda c: 25.0 * np.eye(3),
        "level": lambda c: 0.99,
    },
    "plane.to_polar": {"points": lambda c: _arc(), "site": lambda c: np.zeros(3)},
    "plane.from_polar": {
        "polar": lambda c: plane.to_polar(_arc(), np.zeros(3)),
        "site": lambda c: np.zeros(3),
    },
    "plane.radar_covariances": {
        "points": lambda c: _arc() + np.array([0, 0, 5e3]),
        "site": lambda c: np.zeros(3),
        "sigma_range": lambda c: 30.0,
        "sigma_azimuth": lambda c: 1e-3,
        "sigma_elevation": lambda c: 1e-3,
    },
    # --------------------------------------------------------- trajectories
    "trajectories.TrajectoryData": {
        "times": lambda c: list(_T),
        "values": lambda c: [2 * _T[0], -_T[1] + 0.5 * (_T[1] % 2)],
        "sigma2": lambda c: 1.0,
        "epoch": lambda c: 0.0,
    },
    "trajectories.closed_form": {"data": _td, "family": lambda c: "diverging"},
    "trajectories.solve": {
        "data": _td,
        "family": lambda c: "parallel",
        "solver": lambda c: "CLARABEL",
    },
    "trajectories.family_test": {
        "data": _td,
        "family": lambda c: "diverging",
        "level": lambda c: 0.95,
    },
    "trajectories.covariance": {"data": _td, "family": lambda c: "diverging"},
    "trajectories.design_matrix": {"data": _td, "family": lambda c: "diverging"},
    "trajectories.variance_ratios": {"data": _td, "family": lambda c: "diverging"},
    "trajectories.constraint_residuals": {
        "data": _td,
        "family": lambda c: "diverging",
        "start": lambda c: _tcf(c).start,
        "velocity": lambda c: _tcf(c).velocity,
    },
    "trajectories.objective": {
        "data": _td,
        "start": lambda c: _tcf(c).start,
        "velocity": lambda c: _tcf(c).velocity,
    },
    "trajectories.predict": {
        "data": _td,
        "start": lambda c: _tcf(c).start,
        "velocity": lambda c: _tcf(c).velocity,
    },
    "trajectories.eta": {"n": lambda c: 10, "q": lambda c: 2},
    "trajectories.eta0": {"q": lambda c: 2},
    "trajectories.independent_variances": {
        "n": lambda c: 10,
        "dt": lambda c: 1.0,
        "sigma2": lambda c: 1.0,
    },
    "trajectories.paper_covariance": {
        "family": lambda c: "diverging",
        "n": lambda c: 10,
        "dt": lambda c: 1.0,
        "sigma2": lambda c: 1.0,
    },
    # --------------------------------------------------------------- fusion
    "fusion.fuse": {
        "a1": lambda c: np.array([1.0, 2.0]),
        "s1": lambda c: _S1,
        "a2": lambda c: np.array([1.5, 1.0]),
        "s2": lambda c: _S2,
    },
    "fusion.weight_matrix": {"s1": lambda c: _S1, "s2": lambda c: _S2},
    "fusion.weight_matrix_correlated": {
        "s1": lambda c: _S1,
        "s2": lambda c: _S2,
        "s12": lambda c: 0.1 * np.eye(2),
    },
    "fusion.fused_covariance": {
        "w": lambda c: fu.weight_matrix(_S1, _S2),
        "s1": lambda c: _S1,
        "s2": lambda c: _S2,
    },
    "fusion.weight_covariance": {
        "s1": lambda c: _S1,
        "s2": lambda c: _S2,
        "n1": lambda c: 30,
        "n2": lambda c: 30,
    },
    "fusion.weight_jacobians": {"s1": lambda c: _S1, "s2": lambda c: _S2},
    "fusion.weight_from_samples": {
        "a1": lambda c: np.random.default_rng(1).normal(size=(40, 2)),
        "a2": lambda c: np.random.default_rng(2).normal(size=(40, 2)),
    },
    "fusion.sample_covariance_moments": {"sigma": lambda c: _S1, "n": lambda c: 30},
    "fusion.monte_carlo_weight": {
        "s1": lambda c: _S1,
        "s2": lambda c: _S2,
        "n1": lambda c: 10,
        "n2": lambda c: 10,
        "trials": lambda c: 50,
        "seed": lambda c: 1,
    },
    "fusion.commutation_matrix": {"m": lambda c: 3},
    "fusion.TwoSiteSystem": {
        "site_a": lambda c: np.array([-1e4, 0.0]),
        "site_b": lambda c: np.array([1e4, 0.0]),
        "sigma_azimuth": lambda c: 3e-3,
        "sigma_range_difference": lambda c: 3.0,
    },
    # ------------------------------------------------------------ biasfield
    "biasfield.FieldData": {
        "radars": lambda c: _fd(c).radars,
        "centers": lambda c: _fd(c).centers,
        "xi": lambda c: _fd(c).xi,
        "adjacency": lambda c: _fd(c).adjacency,
        "P": lambda c: _fd(c).P,
    },
    "biasfield.closed_form": {"data": _fd},
    "biasfield.solve": {"data": _fd, "box": lambda c: (500.0, 0.01)},
    "biasfield.solve_lipschitz": {"data": _fd},
    "biasfield.uncertainty_sets": {"data": _fd},
    "biasfield.field_map": {"solution": _fsol, "data": _fd},
    "biasfield.FieldMap": {"centers": lambda c: _fd(c).centers, "field": lambda c: _fsol(c).field},
    "biasfield.score": {
        "field": lambda c: _fsol(c).field,
        "truth": lambda c: np.zeros_like(_fsol(c).field),
        "data": _fd,
    },
    "biasfield.synthetic_field_data": {"seed": lambda c: 0, "cells": lambda c: 8},
    "biasfield.laplacian": {
        "centers": lambda c: _fd(c).centers,
        "adjacency": lambda c: _fd(c).adjacency,
    },
    "biasfield.neighbours": {"centers": lambda c: _fd(c).centers},
    "biasfield.place_centers": {"points": lambda c: _fd(c).centers, "count": lambda c: 4},
    "biasfield.to_polar": {"x": lambda c: _fd(c).centers, "site": lambda c: np.zeros(2)},
    "biasfield.from_polar": {
        "polar": lambda c: bf.to_polar(_fd(c).centers, np.zeros(2)),
        "site": lambda c: np.zeros(2),
    },
    "biasfield.polar_jacobian": {"x": lambda c: _fd(c).centers, "site": lambda c: np.zeros(2)},
    "biasfield.bias_from_shift": {
        "x": lambda c: _fd(c).centers,
        "site": lambda c: np.zeros(2),
        "s": lambda c: np.ones_like(_fd(c).centers),
    },
    "biasfield.shift_from_bias": {
        "x": lambda c: _fd(c).centers,
        "site": lambda c: np.zeros(2),
        "f": lambda c: np.ones_like(_fd(c).centers) * [5.0, 1e-3],
    },
    "biasfield.wrap_angle": {"a": lambda c: np.linspace(-10, 10, 7)},
    "biasfield.hat_basis": {
        "t": lambda c: np.linspace(0, 10, 9),
        "knots": lambda c: np.arange(0.0, 12.0, 2.0),
    },
    "biasfield.fl_to_height": {"pressure_altitude": lambda c: np.array([1000.0, 9000.0])},
    "biasfield.PlotTable": {
        "time": lambda c: np.arange(3.0),
        "radar": lambda c: np.array([0, 1, 0]),
        "range": lambda c: np.array([1e3, 2e3, 3e3]),
        "azimuth": lambda c: np.array([0.1, 0.2, 0.3]),
        "object": lambda c: np.array([-1, 0, 0]),
    },
    "biasfield.RadarSet": {
        "sites": lambda c: np.array([[0.0, 0.0], [4e4, 0.0]]),
        "sigma_range": lambda c: np.array([30.0, 30.0]),
        "sigma_azimuth": lambda c: np.array([1e-3, 1e-3]),
        "max_range": lambda c: np.array([2.5e5, 2.5e5]),
    },
    "biasfield.seen_by_others": {"plots": lambda c: _net(c).plots},
    "biasfield.fit_tracks": {"plots": lambda c: _net(c).plots, "radars": lambda c: _net(c).radars},
    "biasfield.correct_plots": {
        "plots": lambda c: _net(c).plots,
        "radars": lambda c: _net(c).radars,
        "field": lambda c: _net_map(c),
    },
    "biasfield.registration_error": {
        "plots": lambda c: _net(c).plots,
        "radars": lambda c: _net(c).radars,
    },
    "biasfield.read_radars": {"path": _radars_csv},
    "biasfield.to_frame": {"table": lambda c: _net(c).plots},
    "biasfield.from_frame": {"df": lambda c: bf.to_frame(_net(c).plots)},
    # ----------------------------------------------------------- assignment
    "assignment.AssignmentData": {
        "means": lambda c: _ad(c).means,
        "covs": lambda c: _ad(c).covs,
        "measurements": lambda c: _ad(c).measurements,
        "meas_cov": lambda c: _ad(c).meas_cov,
        "volume": lambda c: 400.0,
        "pd": lambda c: 0.9,
        "rho": lambda c: 0.2,
    },
    "assignment.solve": {"data": _ad, "mip_gap": lambda c: 0.0},
    "assignment.brute_force": {"data": _ad},
    "assignment.linear_assignment": {"data": _ad},
    "assignment.k_best": {"data": _ad, "k": lambda c: 2},
    "assignment.soft_marginals": {"data": _ad},
    "assignment.candidate_groups": {"data": _ad},
    "assignment.log_likelihoods": {"data": _ad, "groups": lambda c: [(0,), (1,)]},
    "assignment.block_log_prior": {
        "data": _ad,
        "group": lambda c: (0,),
        "detected": lambda c: True,
    },
    "assignment.enumerate_hypotheses": {"data": _ad},
    "assignment.count_hypotheses": {"q": lambda c: 2, "n": lambda c: 3},
    "assignment.count_per_variant": {"q": lambda c: 2, "n": lambda c: 3},
    "assignment.set_partitions": {"items": lambda c: [0, 1, 2]},
    "assignment.cartesian_to_polar": {
        "points": lambda c: _ad(c).measurements + 100.0,
        "site": lambda c: np.zeros(2),
    },
    "assignment.polar_to_cartesian": {
        "polar": lambda c: np.array([[1e3, 0.1], [2e3, 0.2]]),
        "site": lambda c: np.zeros(2),
    },
    "assignment.polar_measurement_covs": {
        "measurements": lambda c: _ad(c).measurements + 100.0,
        "site": lambda c: np.zeros(2),
        "sigma_range": lambda c: 10.0,
        "sigma_azimuth": lambda c: 1e-3,
    },
    "assignment.Resolution": {"range": lambda c: 50.0, "azimuth": lambda c: 0.01},
    "assignment.effective_gate": {
        "innovation_cov": lambda c: np.eye(2),
        "pd": lambda c: 0.9,
        "clutter_density": lambda c: 1e-4,
    },
    "assignment.reduce_mixture": {
        "weights": lambda c: np.array([0.3, 0.7]),
        "means": lambda c: np.array([[0.0, 0.0], [1.0, 1.0]]),
        "covs": lambda c: np.stack([np.eye(2)] * 2),
    },
    "assignment.score": {
        "data": _ad,
        "partition": lambda c: [(0,), (1,)],
        "assignment": lambda c: [0, 1, -1],
    },
    "biasfield.radar_baseline": {
        "field": lambda c: np.stack(
            [
                np.stack([np.full(6, 20.0 + 5 * i), np.full(6, 1e-3 * (i + 1))], axis=1)
                for i in range(2)
            ],
            axis=1,
        ),
        "centers": lambda c: np.array([[1e4 * k, 5e3 * (k % 2)] for k in range(6)]),
        "sites": lambda c: np.array([[0.0, 0.0], [4e4, 0.0]]),
    },
    # ------------------------------------------------------------------- io
    "io.read_plane_csv": {"path": _plane_csv},
    "io.read_trajectory_csv": {"path": _traj_csv},
    "io.read_csv_rows": {"path": _plane_csv},
    "io.read_text": {"path": _text_file},
    "io.input_file": {"path": _any_file},
    "io.write_plane_csv": {
        "path": lambda c: Out((c.tmp or Path("/tmp")) / "out" / "p.csv"),
        "points": lambda c: _arc(5),
    },
    "io.write_csv": {
        "path": lambda c: Out((c.tmp or Path("/tmp")) / "out" / "r.csv"),
        "rows": lambda c: [{"a": 1.0, "b": 2}],
    },
    "io.markdown_table": {"rows": lambda c: [{"a": 1.0, "b": 2}], "columns": lambda c: ["a", "b"]},
    "io.csv_cell": {"v": lambda c: Anything(1.5)},
}
for _more in (sweep_recipes_io, sweep_recipes_biasfield):
    assert not set(_more.RECIPES) & set(RECIPES), _more.__name__
    RECIPES.update(_more.RECIPES)


def _net_map(c: Ctx) -> bf.FieldMap:
    net = _net(c)
    return c.get(
        "netmap",
        lambda: bf.FieldMap(
            np.array([[-2e5, -2e5], [2e5, -2e5], [0.0, 2e5], [0.0, 0.0]]),
            np.zeros((4, net.radars.m, 2)),
        ),
    )


#: (entry, argument, bad kind) -> why it fails today, for defects in files this sweep's
#: owner does not own (strict xfail: the mark must go when the defect is fixed).
KNOWN: dict[tuple[str, str, str], str] = {}  # found by this sweep; see notes/robust.md


# ------------------------------------------------------------------ bad values
def kinds_for(good: Any) -> list[str]:
    """The kinds of bad value that are bad for any argument whose good value is ``good``."""
    if isinstance(good, Anything):
        return []
    if isinstance(good, Free):
        return ["number", "ragged"]
    if isinstance(good, Out):
        return ["number", "folder"]
    if isinstance(good, AnyFile):
        return ["number", "missing", "folder"]
    if isinstance(good, TextFile):
        return ["number", "missing", "folder", "foreign"]
    if isinstance(good, bool | np.bool_):
        return ["text", "ragged"]
    if isinstance(good, str):
        return ["choice", "number", "ragged"]
    if isinstance(good, Path):
        return ["number", "missing", "folder", "foreign", "empty"]
    if isinstance(good, int | float | np.integer | np.floating):
        return ["text", "complex", "ragged", "nan"]
    if isinstance(good, np.ndarray) or (
        isinstance(good, list | tuple)
        and good
        and all(isinstance(v, int | float | np.integer | np.floating) for v in good)
    ):
        return ["ragged", "text-array", "none-entry", "complex-array", "mapping"]
    if isinstance(good, list | tuple):
        return ["text", "ragged", "mapping"]
    return ["text", "number", "mapping"]


#: one fixed bad value per kind, always tried first (hypothesis's explicit example): a known
#: defect then fails deterministically, whatever the generated examples are
CANON: dict[str, list[Any]] = {
    "text": ["x", "", "1.5"],
    "number": [3.5],
    "choice": ["qxz"],
    "missing": [Path("/proc/optmodels-missing/a")],
    "folder": [Path("/")],
    "complex": [complex(1.0, 1.0)],
    "nan": [float("nan")],
    "mapping": [{"a": 1.0}],
    "ragged": [[[0.0], [1.0, 1.0]]],
    "text-array": [[["a"] * 3] * 2],
    "none-entry": [[[1.0, None, 2.0]] * 2],
    "complex-array": [np.ones((2, 3)) * (1 + 1j)],
    "foreign": [BadFile(FOREIGN_PREFIX + bytes(range(256)) * 4)],
    "empty": [BadFile(b"")],
}


@st.composite
def bad_values(draw: st.DrawFn, kind: str) -> Any:
    """A bad value of ``kind`` (random content, random shape)."""
    if kind == "text":
        return draw(st.sampled_from(["", "x", "1.5", "nan", "None", "[1, 2]"]))
    if kind == "number":
        return draw(st.sampled_from([3.5, -1, 0, 1e300]))
    if kind == "choice":
        return draw(st.text(alphabet="qxzjk_-", min_size=1, max_size=6))
    if kind == "folder":
        return Path("/")
    if kind == "missing":
        # under /proc: it cannot exist and nothing can create it
        return Path("/proc/optmodels-missing") / draw(
            st.text(alphabet="abc", min_size=1, max_size=4)
        )
    if kind == "complex":
        return complex(draw(st.floats(-1e3, 1e3)), draw(st.floats(0.5, 1e3)))
    if kind == "nan":
        return float("nan")
    if kind == "foreign":  # random bytes (a binary file of another kind)
        return BadFile(FOREIGN_PREFIX + draw(st.binary(max_size=300)))
    if kind == "empty":
        return BadFile(b"")
    if kind == "mapping":
        return {"a": 1.0}
    n = draw(st.integers(2, 5))
    if kind == "ragged":
        lens = draw(
            st.lists(st.integers(1, 4), min_size=n, max_size=n).filter(lambda x: len(set(x)) > 1)
        )
        return [[float(i)] * k for i, k in enumerate(lens)]
    if kind == "text-array":
        return [[draw(st.sampled_from(["a", "1,5", "x"]))] * 3 for _ in range(n)]
    if kind == "none-entry":
        row = [1.0, None, 2.0]
        return [row] * n
    if kind == "complex-array":
        return np.ones((n, 3)) * complex(1.0, draw(st.floats(0.5, 2.0)))
    raise AssertionError(kind)


# ------------------------------------------------------------------ the calls
_ENTRIES = public_entries()


#: the good values, built once (at collection for their types; files when a test runs)
_CTX = Ctx(None)


@pytest.fixture(scope="module")
def ctx(tmp_path_factory: pytest.TempPathFactory) -> Ctx:
    _CTX.tmp = tmp_path_factory.mktemp("sweep")
    return _CTX


def _call(name: str, args: dict[str, Any]) -> Any:
    if name == "io.atomic_write":  # a context manager: entered, one line written
        binary = bool(args.get("binary"))
        with _ENTRIES[name](**args) as fh:
            fh.write(b"written\n" if binary else "written\n")
        return Path(args["path"]).read_bytes()
    out = _ENTRIES[name](**args)
    if inspect.isgenerator(out) or name in (
        "assignment.set_partitions",
        "assignment.enumerate_hypotheses",
    ):
        out = list(out)
    return out


def _good(name: str, c: Ctx) -> dict[str, Any]:
    out = {k: make(c) for k, make in RECIPES[name].items()}
    return {k: v.value if isinstance(v, Anything) else v for k, v in out.items()}


def _check_answer(out: Any) -> None:
    """A good call's answer: every Solution in it keeps the contract (OK -> verified)."""
    items = out if isinstance(out, tuple | list) else [out]
    for item in items:
        if isinstance(item, Solution):
            assert_verified(item)
        for attr in ("hypotheses",):
            for sol in getattr(item, attr, []) or []:
                if isinstance(sol, Solution):
                    assert_verified(sol)


def _named(msg: str, arg: str, value: Any) -> bool:
    low = msg.lower()
    return arg.lower() in low or (
        isinstance(value, str | Path) and str(value) and str(value).lower() in low
    )


def _cases() -> list[tuple[str, str, str]]:
    c = _CTX  # the good values' types (files are made when a test runs)
    out = []
    for name in sorted(RECIPES):
        for arg, make in RECIPES[name].items():
            try:
                good = make(c)
            except (AssertionError, TypeError):  # a file (made later): a path's kinds
                good = FILE_FACTORIES.get(make, Path)("x")
            out += [(name, arg, kind) for kind in kinds_for(good)]
    return out


CASES = _cases()


def _materialize(c: Ctx, value: Any) -> Any:
    """A :class:`BadFile` written into the session's folder (its name from its content)."""
    if not isinstance(value, BadFile):
        return value
    import hashlib

    digest = hashlib.sha1(value.content).hexdigest()[:12]
    return make_file(c, f"bad-{digest}.dat", value.content)


def _bad_case(name: str, arg: str, c: Ctx, kind: str, value: Any) -> None:
    value = _materialize(c, value)
    args = _good(name, c)
    args[arg] = value
    try:
        _call(name, args)
    except ProblemError as exc:
        assert _named(str(exc), arg, value), (
            f"{name} {arg}={value!r:.60}: the refusal does not name {arg!r}: {exc}"
        )
        return
    except SolverNotAvailable as exc:  # an unknown solver name: the documented refusal
        assert arg in ("solver", "plugin") and _named(str(exc), arg, value), exc
        return
    except OptModelsError as exc:
        raise AssertionError(
            f"{name} {arg}={value!r:.60}: {type(exc).__name__} instead of ProblemError: {exc}"
        ) from exc
    except Exception as exc:  # a raw exception: the finding this sweep exists for
        raise AssertionError(
            f"{name} {arg}={value!r:.60}: raw {type(exc).__name__}: {exc}"
        ) from exc
    raise AssertionError(f"{name} {arg}={value!r:.60} ({kind}): accepted silently")


def _params(name: str, arg: str, kind: str) -> Any:
    mark = KNOWN.get((name, arg, kind))
    return pytest.param(
        name,
        arg,
        kind,
        id=f"{name}-{arg}-{kind}",
        marks=[pytest.mark.xfail(strict=True, reason=mark)] if mark else [],
    )


_COMMON = {
    "deadline": None,
    "derandomize": True,
    "report_multiple_bugs": False,
    "phases": (Phase.explicit, Phase.reuse, Phase.generate),  # no shrinking
    "suppress_health_check": [
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.function_scoped_fixture,
    ],
}


def _bad_property(name: str, arg: str, kind: str, c: Ctx, n: int) -> None:
    @settings(max_examples=n, **_COMMON)
    @given(value=bad_values(kind))
    def prop(value: Any) -> None:
        _bad_case(name, arg, c, kind, value)

    for value in CANON[kind]:
        prop = example(value=value)(prop)

    prop()


PAIRS = sorted({(n, a) for n, a, _ in CASES})


def _pair_params(name: str, arg: str) -> Any:
    bad = sorted(k for (n, a, k), _ in KNOWN.items() if (n, a) == (name, arg))
    why = "; ".join(f"{k}: {KNOWN[(name, arg, k)]}" for k in bad)
    return pytest.param(
        name,
        arg,
        id=f"{name}-{arg}",
        marks=[pytest.mark.xfail(strict=True, reason=why)] if bad else [],
    )


def _pair_property(name: str, arg: str, c: Ctx, n: int) -> None:
    kinds = [k for nn, a, k in CASES if (nn, a) == (name, arg)]

    @settings(max_examples=n, **_COMMON)
    @given(data=st.data())
    def prop(data: st.DataObject) -> None:
        kind = data.draw(st.sampled_from(kinds))
        _bad_case(name, arg, c, kind, data.draw(bad_values(kind)))

    for kind in kinds:  # the fixed values first: a known defect fails every run
        for value in CANON[kind]:
            _bad_case(name, arg, c, kind, value)
    prop()


@pytest.mark.parametrize("name, arg", [_pair_params(*pair) for pair in PAIRS])
def test_bad_values_are_one_named_problem_error(name: str, arg: str, ctx: Ctx) -> None:
    """Generated bad values of every kind for one argument: one ProblemError naming it
    (CI: one test per argument; the ``slow`` twin has one per argument and kind)."""
    _pair_property(name, arg, ctx, N_FULL if FULL else N_CI)


@pytest.mark.slow
@pytest.mark.parametrize("name, arg, kind", [_params(*case) for case in CASES])
def test_bad_values_are_one_named_problem_error_full(
    name: str, arg: str, kind: str, ctx: Ctx
) -> None:
    """Per argument and kind, many generated values (``make test-all``)."""
    _bad_property(name, arg, kind, ctx, N_FULL)


# ------------------------------------------------------------------ good values
@pytest.mark.parametrize("name", sorted(RECIPES))
def test_good_values_give_a_verified_answer(name: str, ctx: Ctx) -> None:
    """The recipe's good arguments: an answer (no exception), every Solution verified."""
    _check_answer(_call(name, _good(name, ctx)))


@pytest.mark.parametrize(
    "name", sorted(n for n, o in _ENTRIES.items() if rule(o) == "no arguments (called once)")
)
def test_entry_points_without_arguments(name: str) -> None:
    _ENTRIES[name]()


def _scaled_property(name: str, c: Ctx, n: int) -> None:
    base = _good(name, c)
    arrays = [
        k for k, v in base.items() if isinstance(v, np.ndarray) and v.dtype.kind == "f" and v.size
    ]
    if not arrays:
        return

    @settings(max_examples=n, **_COMMON)
    @given(which=st.sampled_from(arrays), scale=st.sampled_from([1e-6, 1e-2, 0.5, 3.0, 1e4]))
    def prop(which: str, scale: float) -> None:
        args = dict(base)
        args[which] = base[which] * scale
        try:
            out = _call(name, args)
        except OptModelsError:
            return
        _check_answer(out)

    prop()


@pytest.mark.parametrize("name", sorted(RECIPES))
def test_rescaled_good_values_are_verified_or_refused(name: str, ctx: Ctx) -> None:
    """Any positive rescaling of one numeric array argument: a verified answer or an
    optmodels refusal -- never a raw exception, never an OK status that fails the check."""
    _scaled_property(name, ctx, N_FULL if FULL else 2)


# ------------------------------------------------------------------ coverage
def test_every_public_entry_point_is_swept() -> None:
    """Every public name is a recipe or falls under a rule; the recipes name only public
    entries and real parameters (so the sweep's list is the packages' __all__)."""
    missing = sorted(
        n for n, o in _ENTRIES.items() if rule(o) is None and n not in RECIPES and n not in NOT_YET
    )
    assert not missing, f"public entry points without a recipe: {missing}"
    for name, recipe in RECIPES.items():
        assert name in _ENTRIES, f"{name} is not public (not in an __all__)"
        params = inspect.signature(_ENTRIES[name]).parameters
        assert set(recipe) <= set(params), (name, set(recipe) - set(params))
        required = {
            k
            for k, p in params.items()
            if p.default is p.empty and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)
        }
        assert required <= set(recipe), (name, required - set(recipe))
    for name in NOT_YET:
        assert name in _ENTRIES and rule(_ENTRIES[name]) is None, name
        assert name not in RECIPES, f"{name} has a recipe: take it off NOT_YET"


#: public entry points without a recipe yet, each with the reason (kept by the recipe
#: modules; the coverage test keeps the list honest: each must still be public, without
#: a rule and without a recipe).
NOT_YET: dict[str, str] = {**sweep_recipes_io.NOT_YET, **sweep_recipes_biasfield.NOT_YET}
