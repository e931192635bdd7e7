"""Closely spaced space objects observed in sessions (paper 004's setting).

Q objects move with nearly equal constant velocities in a 2-D measurement plane
(along-track, cross-track), spaced by ``separation``. Each session the sensor detects each
object with probability P_D; objects closer than ``resolution`` to each other are
**unresolved** and give one measurement at their mean; Poisson clutter (mean ``clutter``)
falls uniformly in the surveillance window. Everything is seeded and the truth of every
measurement (which block or clutter) is returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csgraph
from scipy.spatial.distance import pdist, squareform

from optmodels import seeds
from optmodels.core import FloatArray, ProblemError, as_count, as_positive, as_probability

__all__ = [
    "MAX_CLUTTER",
    "MAX_OBJECTS",
    "MAX_SESSIONS",
    "Session",
    "SpaceScenario",
    "space_objects",
]

#: Size guards: objects (the pairwise distances are Q × Q per session), sessions, and the
#: mean number of clutter measurements per session.
MAX_OBJECTS, MAX_SESSIONS, MAX_CLUTTER = 5000, 100_000, 1e5


@dataclass(frozen=True)
class Session:
    """One observation session: ``time``, ``measurements`` (N, 2), ``truth`` (N,) tuples of
    object indices (the block that produced each measurement; ``()`` for clutter),
    ``positions`` (Q, 2) true positions at the session."""

    time: float
    measurements: FloatArray
    truth: list[tuple[int, ...]]
    positions: FloatArray


@dataclass(frozen=True)
class SpaceScenario:
    """Sessions and the sensor: noise ``meas_cov`` (2, 2), ``pd``, ``window`` (half-size of
    the surveillance square around the group), ``volume``, initial states ``x0`` (Q, 4)."""

    sessions: list[Session]
    meas_cov: FloatArray
    pd: float
    volume: float
    x0: FloatArray
    resolution: float


def space_objects(
    seed: int | np.random.Generator,
    *,
    q: int = 4,
    sessions: int = 12,
    separation: float = 100.0,
    resolution: float = 150.0,
    sigma: float = 30.0,
    pd: float = 0.9,
    clutter: float = 2.0,
    dt: float = 60.0,
    window: float = 2000.0,
) -> SpaceScenario:
    """Q objects released in a line with spacing ``separation`` (m) and relative drifts of
    ±0.2 m/s, observed every ``dt`` s with noise σ = ``sigma`` m per axis.

    Parameters
    ----------
    seed : int or numpy.random.Generator
    q, sessions : int
        Objects (1..:data:`MAX_OBJECTS`) and sessions (1..:data:`MAX_SESSIONS`).
    separation, resolution, sigma, dt, window : float
        Metres, metres, metres, seconds, metres; positive and finite.
    pd : float
        Detection probability in [0, 1].
    clutter : float
        Mean clutter count per session, in [0, :data:`MAX_CLUTTER`].

    Raises
    ------
    ProblemError
        Naming the argument, for a wrong type or value.
    """
    w = "scenarios.space_objects"
    rng = seeds.as_generator(f"{w} seed", seed, allow_none=True)
    q = as_count(f"{w} q", q, minimum=1, maximum=MAX_OBJECTS)
    sessions = as_count(f"{w} sessions", sessions, minimum=1, maximum=MAX_SESSIONS)
    separation = as_positive(f"{w} separation", separation)
    resolution = as_positive(f"{w} resolution", resolution)
    sigma = as_positive(f"{w} sigma", sigma)
    pd = as_probability(f"{w} pd", pd)
    clutter = as_positive(f"{w} clutter", clutter, allow_zero=True)
    if clutter > MAX_CLUTTER:
        raise ProblemError(f"{w} clutter: must be <= {MAX_CLUTTER:g}, got {clutter:g}")
    dt = as_positive(f"{w} dt", dt)
    window = as_positive(f"{w} window", window)
    pos0 = np.column_stack([np.arange(q) * separation, rng.normal(0, 0.1 * separation, q)])
    vel = np.column_stack([np.full(q, 7000.0), np.zeros(q)]) + rng.uniform(-0.2, 0.2, (q, 2))
    x0 = np.hstack([pos0, vel])
    cov = sigma**2 * np.eye(2)
    out = []
    for s in range(sessions):
        t = s * dt
        pos = pos0 + vel * t
        # unresolved groups: connected components of "closer than the resolution"
        close = squareform(pdist(pos)) < resolution if q > 1 else np.zeros((1, 1), bool)
        _, label = csgraph.connected_components(close, directed=False)
        meas, truth = [], []
        for lab in np.unique(label):
            members = tuple(int(j) for j in np.flatnonzero(label == lab))
            if rng.random() < pd:
                meas.append(
                    pos[list(members)].mean(axis=0) + rng.multivariate_normal(np.zeros(2), cov)
                )
                truth.append(members)
        centre = pos.mean(axis=0)
        for _ in range(rng.poisson(clutter)):
            meas.append(centre + rng.uniform(-window, window, 2))
            truth.append(())
        order = rng.permutation(len(meas))
        out.append(
            Session(
                t, np.array(meas, dtype=float).reshape(-1, 2)[order], [truth[k] for k in order], pos
            )
        )
    return SpaceScenario(out, cov, pd, (2 * window) ** 2, x0, resolution)
