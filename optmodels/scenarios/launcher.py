"""Families of objects on dependent linear trajectories (paper 002).

* :func:`launcher_release`: objects released by one launcher. In the modified orbital
  frame of the paper's reference [1] the along-track coordinate of each object is linear
  in time; objects released together share the start (the release point at the release
  instant) and differ in velocity (diverging family); objects spaced along the same orbit
  share the drift velocity and differ in start (parallel family).
* :func:`equally_spaced`: the paper's own setting for (15)-(20) and the conclusions: every
  object measured at ``t_i = (i − 1)·ΔT``, ``i = 1..N``.

Every generator takes a seed or a ``numpy.random.Generator`` and returns the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from optmodels import seeds
from optmodels.core import FloatArray, ProblemError, as_choice, as_count, as_positive
from optmodels.trajectories import TrajectoryData

__all__ = ["TrajectoryScenario", "equally_spaced", "launcher_release"]


@dataclass(frozen=True)
class TrajectoryScenario:
    """Measurements of ``Q`` objects with their true lines.

    Attributes
    ----------
    times, values : lists of Q arrays (s; m)
    start, velocity : (Q,) true lines at ``t = 0`` (m, m/s)
    sigma2 : float, measurement error variance (m²)
    family : str, the family the truth belongs to
    """

    times: list[FloatArray]
    values: list[FloatArray]
    start: FloatArray
    velocity: FloatArray
    sigma2: float
    family: str

    def data(self) -> TrajectoryData:
        return TrajectoryData(self.times, self.values, self.sigma2)


def _rng(seed: int | np.random.Generator | None, where: str) -> np.random.Generator:
    """A Generator as given, seeded from a whole number >= 0 (or a sequence of them), or a
    fresh one for ``None`` (:func:`optmodels.seeds.as_generator`)."""
    return seeds.as_generator(f"{where} seed", seed, allow_none=True)


def _measure(
    rng: np.random.Generator,
    times: list[FloatArray],
    start: FloatArray,
    velocity: FloatArray,
    sigma2: float,
) -> list[FloatArray]:
    return [
        start[j] + velocity[j] * t + rng.normal(0.0, np.sqrt(sigma2), t.size)
        for j, t in enumerate(times)
    ]


def launcher_release(
    seed: int | np.random.Generator | None = None,
    *,
    family: Literal["diverging", "parallel"] = "diverging",
    q: int = 4,
    sigma: float = 150.0,
) -> TrajectoryScenario:
    """Objects of one launch seen by a radar with unequal, object-specific schedules.

    Diverging: released at ``t = 0`` from the along-track position 0 with relative
    velocities spread over about ±4 m/s; the radar tracks each object from 60-200 s
    after release for 10-30 minutes at 10 s intervals, with gaps (unequal N_j and times).
    Parallel: the same objects spaced 2-20 km apart, all drifting at 1.5 m/s.
    ``sigma`` (m) is the along-track measurement error.

    Raises
    ------
    ProblemError
        ``q`` not a whole number ≥ 2, ``sigma`` not positive, an unknown ``family``, a
        seed that is neither a Generator, None nor a whole number.
    """
    where = "scenarios.launcher_release"
    q = as_count(f"{where} q", q)
    if q < 2:
        raise ProblemError(f"{where} q: a family needs at least 2 objects, got {q}")
    family = as_choice(f"{where} family", family, ("diverging", "parallel"))  # type: ignore
    sigma = as_positive(f"{where} sigma", sigma)
    rng = _rng(seed, where)
    times: list[FloatArray] = []
    for _ in range(q):
        first = rng.uniform(60.0, 200.0)
        n = int(rng.integers(60, 181))
        t = first + 10.0 * np.arange(n)
        keep = rng.random(n) > 0.3  # missed detections
        keep[:2] = True
        times.append(np.asarray(t[keep], dtype=float))
    if family == "diverging":
        start = np.zeros(q)
        velocity = np.sort(rng.uniform(-4.0, 4.0, q))
    elif family == "parallel":
        start = np.cumsum(rng.uniform(2e3, 20e3, q))
        velocity = np.full(q, 1.5)
    else:  # pragma: no cover - as_choice above
        raise ProblemError(f"family: expected 'diverging' or 'parallel', got {family!r}")
    s2 = sigma * sigma
    return TrajectoryScenario(
        times, _measure(rng, times, start, velocity, s2), start, velocity, s2, family
    )


def equally_spaced(
    seed: int | np.random.Generator | None = None,
    *,
    n: int = 10,
    q: int = 2,
    dt: float = 1.0,
    family: str = "diverging",
    sigma2: float = 1.0,
) -> TrajectoryScenario:
    """The paper's setting of (15)-(20): ``Q`` objects measured together at
    ``t_i = (i − 1)·dt``, ``i = 1..N`` (the first measurement at the common start).
    ``dt`` in s, ``sigma2`` in m².

    Raises
    ------
    ProblemError
        ``n`` < 2 or ``q`` < 1 or not whole numbers, ``dt`` or ``sigma2`` not positive, an
        unknown ``family``.
    """
    where = "scenarios.equally_spaced"
    n = as_count(f"{where} n", n, minimum=2)
    q = as_count(f"{where} q", q, minimum=1)
    dt = as_positive(f"{where} dt", dt)
    sigma2 = as_positive(f"{where} sigma2", sigma2)
    family = as_choice(f"{where} family", family, ("diverging", "parallel", "independent"))
    rng = _rng(seed, where)
    t = dt * np.arange(n, dtype=float)
    times = [t.copy() for _ in range(q)]
    if family == "diverging":
        start, velocity = np.zeros(q), np.linspace(-1.0, 1.0, q)
    elif family == "parallel":
        start, velocity = np.linspace(0.0, 10.0, q), np.full(q, 0.5)
    elif family == "independent":
        start, velocity = np.linspace(0.0, 10.0, q), np.linspace(-1.0, 1.0, q)
    else:
        raise ProblemError(f"family: unknown {family!r}")
    return TrajectoryScenario(
        times, _measure(rng, times, start, velocity, sigma2), start, velocity, sigma2, family
    )
