"""The built-in Monte Carlo studies, one per paper (:data:`STUDIES`, :func:`study`).

A study is a picklable callable ``study(rng) -> dict[str, float]`` (here frozen dataclasses,
their parameters checked when built), optionally with ``summarise(values)``. Each imports
its problem package inside the trial, so that a worker process loads only what it runs.
Plane angle error vs the CRB (000), trajectories η vs Monte Carlo (002), Cov(vec Ŵ) vs (10)
(003), bias-field recovery error (001), association rate vs separation (004).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from optmodels.core import (
    ProblemError,
    as_count,
    as_positive,
    check_spd,
)

__all__ = ["STUDIES", "AssignmentSeparation", "BiasfieldRecovery", "FusionWeight",
           "PlaneAngle", "Study", "TrajectoriesEta", "study"]


Study = Callable[[np.random.Generator], Mapping[str, float]]


@dataclass(frozen=True)
class PlaneAngle:
    """Plane of maneuver (paper 000): angle error (rad) of the ML plane and of the
    unweighted SVD plane, and the Cramér–Rao bound of the angle for the trial's truth.
    ``setting``: "two-source" (D_i = α_i² D, closed form) or "radar" (general D_i,
    reduced NLP)."""

    name: ClassVar[str] = "plane-angle"
    problem: ClassVar[str] = "plane"

    n: int = 50
    setting: str = "radar"

    def __post_init__(self) -> None:
        _set(self, "n", as_count("montecarlo.PlaneAngle n", self.n, minimum=3))
        if self.setting not in ("radar", "two-source"):
            raise ProblemError(f"montecarlo.PlaneAngle setting: expected 'radar' or "
                               f"'two-source', got {self.setting!r}")

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import plane, scenarios

        sc = (scenarios.two_source_plane(self.n, rng) if self.setting == "two-source"
              else scenarios.radar_plane(self.n, rng, geometry="broadside"))
        data = plane.PlaneData(sc.points, sc.cov, sc.alpha2)
        ml = (plane.closed_form(data) if data.proportional
              else plane.solve(data, "reduced")).require_ok()
        crb = plane.cramer_rao_bound(plane.PlaneData(sc.truth, sc.cov, sc.alpha2),
                                     sc.normal, sc.offset)
        return {"ml": float(plane.angle_error(ml.normal, sc.normal)),
                "svd": float(plane.angle_error(plane.svd_fit(data).normal, sc.normal)),
                "crb2": float(crb.angle_rms ** 2)}

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        crb = float(np.sqrt(np.mean(v["crb2"])))
        return {"rmse_ml": float(np.sqrt(np.mean(v["ml"] ** 2))),
                "rmse_svd": float(np.sqrt(np.mean(v["svd"] ** 2))), "crb": crb,
                "ml_over_crb": float(np.sqrt(np.mean(v["ml"] ** 2))) / crb}


@dataclass(frozen=True)
class TrajectoriesEta:
    """Dependent linear trajectories (paper 002): squared errors of object 0's velocity
    (the unique parameter of a diverging family) from the dependent fit and from its own
    independent line; Q objects at t = 0..N−1, σ = 1. The ratio of the means is η."""

    name: ClassVar[str] = "trajectories-eta"
    problem: ClassVar[str] = "trajectories"

    q: int = 2
    n: int = 10

    def __post_init__(self) -> None:
        _set(self, "q", as_count("montecarlo.TrajectoriesEta q", self.q, minimum=1))
        _set(self, "n", as_count("montecarlo.TrajectoriesEta n", self.n, minimum=2))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import trajectories as tr

        t = np.arange(self.n, dtype=float)
        v = rng.uniform(-2, 2, self.q)
        vals = [5.0 + v[j] * t + rng.normal(0, 1, self.n) for j in range(self.q)]
        data = tr.TrajectoryData([t] * self.q, vals, 1.0)
        dep = tr.closed_form(data, "diverging")
        ind = tr.closed_form(data, "independent")
        return {"dep": float((dep.velocity[0] - v[0]) ** 2),
                "ind": float((ind.velocity[0] - v[0]) ** 2)}

    def summarise(self, v: Mapping[str, np.ndarray]) -> dict[str, float]:
        from optmodels import trajectories as tr

        return {"eta_mc": float(np.mean(v["dep"]) / np.mean(v["ind"])),
                "eta_formula": tr.eta(self.n, self.q)}


@dataclass(frozen=True)
class FusionWeight:
    """Fusion (paper 003): Ŵ from n snapshots of two independent estimators (sample
    covariances about the sample mean), vec Ŵ per trial; the summary compares its sample
    covariance with the linearised (10)."""

    name: ClassVar[str] = "fusion-weight"
    problem: ClassVar[str] = "fusion"

    n: int = 30
    s1: tuple[tuple[float, ...], ...] = ((1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, 3.0))
    s2: tuple[tuple[float, ...], ...] = ((2.0, 0.5, 0.0), (0.5, 1.0, 0.2), (0.0, 0.2, 1.5))

    def __post_init__(self) -> None:
        from optmodels.core import as_finite_array

        mats = []
        for key in ("s1", "s2"):
            m = as_finite_array(f"montecarlo.FusionWeight {key}", getattr(self, key), ndim=2)
            if m.shape[0] != m.shape[1] or m.shape[0] < 1:
                raise ProblemError(f"montecarlo.FusionWeight {key}: expected a square "
                                   f"matrix, got shape {m.shape}")
            check_spd(f"montecarlo.FusionWeight {key}", m)
            mats.append(m)
            _set(self, key, tuple(tuple(float(x) for x in row) for row in m))
        if mats[0].shape != mats[1].shape:
            raise ProblemError(f"montecarlo.FusionWeight s2: shape {mats[1].shape} differs "
                               f"from s1's {mats[0].shape}")
        # sample covariances about the sample mean need n > m snapshots
        _set(self, "n", as_count("montecarlo.FusionWeight n", self.n,
                                 minimum=mats[0].shape[0] + 1))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import fusion as fu

        s1, s2 = np.array(self.s1), np.array(self.s2)
        m = s1.shape[0]
        a1 = rng.multivariate_normal(np.zeros(m), s1, self.n)
        a2 = rng.multivariate_normal(np.zeros(m), s2, self.n)
        w = fu.weight_from_samples(a1, a2).ravel(order="F")
        return {f"w{k}": float(x) for k, x in enumerate(w)}

    def summarise(self, v: Mapping[str, np.ndarray]) -> dict[str, float]:
        from optmodels import fusion as fu

        s1, s2 = np.array(self.s1), np.array(self.s2)
        w = np.column_stack([v[f"w{k}"] for k in range(s1.size)])
        emp = np.diag(np.cov(w, rowvar=False))
        lin = np.diag(fu.weight_covariance(s1, s2, self.n, self.n, mean="sample"))
        return {"max_rel_diff_diag": float(np.max(np.abs(emp - lin) / lin)),
                "var_mc_mean": float(np.mean(emp)), "var_linear_mean": float(np.mean(lin))}


@dataclass(frozen=True)
class BiasfieldRecovery:
    """Bias field (paper 001): RMS error of the closed-form smoothest field (11) against
    the true smooth field, range (m) and azimuth (mrad), on synthetic uncertainty sets with
    ``noise`` metres of position noise."""

    name: ClassVar[str] = "biasfield-recovery"
    problem: ClassVar[str] = "biasfield"

    cells: int = 200
    noise: float = 20.0

    def __post_init__(self) -> None:
        _set(self, "cells", as_count("montecarlo.BiasfieldRecovery cells", self.cells,
                                     minimum=3))
        _set(self, "noise", as_positive("montecarlo.BiasfieldRecovery noise", self.noise,
                                        allow_zero=True))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import biasfield as bf

        data, truth = bf.synthetic_field_data(rng, cells=self.cells, noise=self.noise)
        f = bf.closed_form(data).require_ok().field
        err = f - truth
        return {"range_rms_m": float(np.sqrt(np.mean(err[..., 0] ** 2))),
                "azimuth_rms_mrad": float(np.sqrt(np.mean(err[..., 1] ** 2)) * 1e3)}


@dataclass(frozen=True)
class AssignmentSeparation:
    """Assignment (paper 004): two objects ``separation`` measurement-σ apart; below
    ``resolution`` σ the sensor returns one merged mark at the centroid, else one each
    (detection probability 1, no clutter in the truth, ρ = 0.05 in the model). A trial
    scores 1 when the MAP hypothesis gets the resolution right (merged vs not) and
    pairs every mark with its source."""

    name: ClassVar[str] = "assignment-separation"
    problem: ClassVar[str] = "assignment"

    separation: float = 1.0
    resolution: float = 1.5
    prior_sigma: float = 0.5

    def __post_init__(self) -> None:
        for key in ("separation", "resolution"):
            _set(self, key, as_positive(f"montecarlo.AssignmentSeparation {key}",
                                        getattr(self, key), allow_zero=True))
        _set(self, "prior_sigma", as_positive("montecarlo.AssignmentSeparation prior_sigma",
                                              self.prior_sigma))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import assignment as asg

        truth = np.array([[0.0, 0.0], [self.separation, 0.0]])
        means = truth + rng.normal(0, self.prior_sigma, (2, 2))
        covs = np.stack([np.eye(2) * self.prior_sigma**2] * 2)
        merged = self.separation < self.resolution
        marks = (truth.mean(axis=0, keepdims=True) if merged else truth)
        meas = marks + rng.normal(0, 1.0, marks.shape)
        side = 20.0
        data = asg.AssignmentData(means, covs, meas, np.eye(2), side**2, 0.95, 0.05)
        sol = asg.solve(data).require_ok()
        blocks = [tuple(sorted(b)) for b in sol.partition]
        if merged:
            ok = blocks == [(0, 1)] and int(sol.assignment[0]) == 0
        else:
            ok = sorted(blocks) == [(0,), (1,)] and all(
                int(sol.assignment[k]) == b[0] for k, b in enumerate(sol.partition))
        return {"correct": float(ok)}

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        p = float(np.mean(v["correct"]))
        return {"rate": p, "se": float(np.sqrt(p * (1 - p) / v["correct"].size))}


def _declared() -> dict[str, Callable[..., Study]]:
    """The studies of this module, each declaring its ``name`` and ``problem`` (class
    attributes), in the order of :mod:`optmodels.registry` (then by name): a new problem's
    study is its class here, no list to edit."""
    from optmodels import registry

    order = {p: i for i, p in enumerate(registry.names())}
    found = [c for c in globals().values() if isinstance(c, type) and c.__module__ == __name__
             and isinstance(c.__dict__.get("name"), str) and "problem" in c.__dict__]
    found.sort(key=lambda c: (order.get(c.problem, len(order)), c.name))
    return {c.name: c for c in found}


#: Built-in studies by name (the CLI's ``optmodels montecarlo NAME``): every study class
#: of this module (:func:`_declared`).
STUDIES: dict[str, Callable[..., Study]] = _declared()


def study(name: str, **params: Any) -> Study:
    """A built-in study by name, e.g. ``study("plane-angle", n=100)``."""
    return _builtin(name, params)


def _set(obj: Any, key: str, value: Any) -> None:
    object.__setattr__(obj, key, value)  # the studies are frozen dataclasses


def _builtin(name: str, params: Any) -> Study:
    if not isinstance(name, str) or name not in STUDIES:
        raise ProblemError(f"montecarlo.run study: unknown study {name!r} "
                           f"(built-in: {sorted(STUDIES)})")
    if not isinstance(params, Mapping) or not all(isinstance(k, str) for k in params):
        raise ProblemError(f"montecarlo.run params: expected a mapping of parameter "
                           f"names to values, got {type(params).__name__}")
    cls = STUDIES[name]
    known = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ProblemError(f"montecarlo.run params: unknown parameter(s) {unknown} of "
                           f"study {name!r} (it takes {known})")
    return cls(**params)
