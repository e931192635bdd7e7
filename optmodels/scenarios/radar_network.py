"""Several 2-D surveillance radars observing aircraft, with position-dependent bias fields
(paper 001, (1)).

Each radar's beam turns clockwise with its own period and phase; a plot is produced when
the beam crosses the aircraft, so reports are asynchronous (no two radars see an object at
the same instant, as the paper assumes). The plot is the true polar position plus the
radar's bias field f_i(x) plus Gaussian polar noise (σ_range, σ_azimuth). Aircraft fly
piecewise-straight paths joined by constant-rate turns. Everything is seeded.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield.data import AircraftPaths, PlotTable, RadarSet
from optmodels.biasfield.fields import BiasField
from optmodels.biasfield.geometry import shift_from_bias, to_polar, wrap_angle
from optmodels.core import FloatArray, ProblemError, as_finite_array

__all__ = ["AircraftPaths", "RadarNetworkScenario", "fly_paths", "radar_network",
           "simulate_plots"]

#: Default network: four radars on a ~200 km square, typical en-route accuracy.
#: Default azimuth noise, 0.08° (rad).
SIGMA_AZIMUTH = float(np.deg2rad(0.08))
DEFAULT_SITES = np.array([[-90e3, -60e3], [100e3, -70e3], [80e3, 110e3], [-70e3, 90e3]])


def fly_paths(rng: np.random.Generator, n_aircraft: int, duration: float, *,
              region: float = 150e3, speed: tuple[float, float] = (150.0, 250.0),
              turn_rate: tuple[float, float] = (0.3, 1.0), dt: float = 1.0) -> AircraftPaths:
    """Aircraft entering at random times and places in a square of half-side ``region``,
    flying legs of 2-10 min joined by turns of ``turn_rate`` °/s lasting 20-90 s
    (``turn_rate=(0, 0)``: straight paths)."""
    times = np.arange(0.0, float(duration) + dt, dt)
    nt = times.size
    pos = np.empty((n_aircraft, nt, 2))
    active = np.zeros((n_aircraft, nt), dtype=bool)
    for a in range(n_aircraft):
        start = rng.uniform(0.0, 0.3 * duration)
        stop = min(duration, start + rng.uniform(0.4, 1.0) * duration)
        heading = rng.uniform(-np.pi, np.pi)
        v = rng.uniform(*speed)
        rate = np.zeros(nt)
        k = 0
        while k < nt:
            leg = int(rng.uniform(120, 600) / dt)
            turn = int(rng.uniform(20, 90) / dt)
            rate[k + leg:k + leg + turn] = np.deg2rad(rng.uniform(*turn_rate)) * rng.choice(
                [-1, 1])
            k += leg + turn
        psi = heading + np.cumsum(rate) * dt
        vel = v * np.column_stack([np.sin(psi), np.cos(psi)])  # heading clockwise from North
        p0 = rng.uniform(-region, region, 2)
        pos[a] = p0 + np.cumsum(vel, axis=0) * dt - vel[0] * dt
        active[a] = (times >= start) & (times <= stop)
    return AircraftPaths(times, pos, active)


def simulate_plots(rng: np.random.Generator, radars: RadarSet, paths: AircraftPaths,
                   fields: Sequence[BiasField], *, periods: ArrayLike | None = None
                   ) -> tuple[PlotTable, FloatArray, FloatArray]:
    """Plots of every radar on every aircraft, and the truth at each plot: true position
    (n, 2) and true polar bias f_i(x) (n, 2).

    The beam of radar i points at φ_i + 2πt/T_i (clockwise from North); the relative
    phase ψ(t) = (φ_i + 2πt/T_i − α_i(x(t)))/2π crosses an integer once per scan, and the
    crossing time (linear interpolation on the path grid, which the 1 s grid resolves for
    periods ≥ 4 s) is the plot time.
    """
    m = radars.m
    if len(fields) != m:
        raise ProblemError(f"fields: need one bias field per radar ({m}), got {len(fields)}")
    per = (np.asarray(periods, dtype=float) if periods is not None
           else rng.uniform(4.0, 12.0, m))
    per = np.broadcast_to(per, (m,))
    if np.any(per < 4.0 * (paths.times[1] - paths.times[0])):
        raise ProblemError("periods: need scan periods of at least 4 path steps")
    phase = rng.uniform(-np.pi, np.pi, m)
    rows: list[tuple[FloatArray, ...]] = []
    for i in range(m):
        for a in range(paths.positions.shape[0]):
            on = paths.active[a]
            t, p = paths.times[on], paths.positions[a, on]
            if t.size < 2:
                continue
            pol = to_polar(p, radars.sites[i])
            psi = (phase[i] + 2 * np.pi * t / per[i] - pol[:, 1]) / (2 * np.pi)
            psi = psi[0] + np.cumsum(np.concatenate([[0.0], wrap_angle(
                2 * np.pi * np.diff(psi)) / (2 * np.pi)]))
            k = np.flatnonzero(np.floor(psi[1:]) > np.floor(psi[:-1]))
            frac = (np.floor(psi[k + 1]) - psi[k]) / (psi[k + 1] - psi[k])
            tk = t[k] + frac * (t[k + 1] - t[k])
            xk = p[k] + frac[:, None] * (p[k + 1] - p[k])
            pk = to_polar(xk, radars.sites[i])
            f = fields[i](xk)
            noise = rng.normal(size=pk.shape) * [radars.sigma_range[i], radars.sigma_azimuth[i]]
            meas = pk + f + noise
            meas[:, 0] = np.abs(meas[:, 0])
            meas[:, 1] = wrap_angle(meas[:, 1])
            seen = meas[:, 0] <= radars.max_range[i]  # the radar reports within its range
            if not seen.any():
                continue
            tk, xk, f, meas = tk[seen], xk[seen], f[seen], meas[seen]
            rows.append((tk, np.full(tk.size, i), meas[:, 0], meas[:, 1],
                         np.full(tk.size, a), xk, f))
    if not rows:
        raise ProblemError("radars: no aircraft within any radar's range")
    cols = [np.concatenate(c) for c in zip(*rows, strict=True)]
    order = np.argsort(cols[0], kind="stable")
    cols = [c[order] for c in cols]
    plots = PlotTable(cols[0], cols[1].astype(np.int64), cols[2], cols[3],
                      cols[4].astype(np.int64))
    return plots, cols[5], cols[6]


@dataclass(frozen=True)
class RadarNetworkScenario:
    """Simulated plots and their truth.

    Attributes
    ----------
    plots : PlotTable
    radars : RadarSet
    fields : list of BiasField, one per radar
    paths : AircraftPaths
    true_position : (n, 2) position of the aircraft at each plot
    true_bias : (n, 2) polar bias f_i(x) at each plot
    """

    plots: PlotTable
    radars: RadarSet
    fields: list[BiasField]
    paths: AircraftPaths
    true_position: FloatArray
    true_bias: FloatArray

    def true_shift(self) -> FloatArray:
        """Cartesian shifts s_i(x) at each plot (n, 2)."""
        out = np.empty_like(self.true_position)
        for i in range(self.radars.m):
            sel = self.plots.radar == i
            out[sel] = shift_from_bias(self.true_position[sel], self.radars.sites[i],
                                       self.true_bias[sel])
        return out


FieldKind = Literal["zero", "constant", "linear", "smooth"]


def radar_network(seed: int | np.random.Generator, *, n_aircraft: int = 30,
                  duration: float = 1800.0, sites: ArrayLike | None = None,
                  fields: FieldKind | Sequence[BiasField] = "smooth",
                  sigma_range: float | ArrayLike = 60.0,
                  sigma_azimuth: float | ArrayLike = SIGMA_AZIMUTH,
                  max_range: float | ArrayLike = 250e3,
                  periods: ArrayLike | None = None, region: float = 150e3,
                  turn_rate: tuple[float, float] = (0.3, 1.0)) -> RadarNetworkScenario:
    """A seeded radar network scenario.

    ``fields``: ``"zero"``; ``"constant"`` (an azimuth bias of ±0.1-0.3° per radar, no range
    bias: the parametric model (2)); ``"linear"``; ``"smooth"`` (a constant plus Gaussian
    bumps: range ±150 m, azimuth ±0.3°); or a list of :class:`BiasField`, one per radar.
    """
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    s = DEFAULT_SITES if sites is None else as_finite_array("sites", sites, ndim=2)
    m = s.shape[0] if s.ndim == 2 else 0
    radars = RadarSet(s, np.broadcast_to(np.asarray(sigma_range, float), (m,)),
                      np.broadcast_to(np.asarray(sigma_azimuth, float), (m,)),
                      np.broadcast_to(np.asarray(max_range, float), (m,)))
    if isinstance(fields, str):
        kinds = ("zero", "constant", "linear", "smooth")
        if fields not in kinds:
            raise ProblemError(f"fields: expected one of {kinds} or a list of BiasField, "
                               f"got {fields!r}")
        flist: list[BiasField] = []
        for i in range(m):
            if fields == "zero":
                flist.append(BiasField.constant(0.0, 0.0))
            elif fields == "constant":
                flist.append(BiasField.constant(
                    0.0, np.deg2rad(rng.uniform(0.1, 0.3)) * rng.choice([-1, 1])))
            elif fields == "linear":
                g = np.array([[rng.uniform(-1, 1) * 1e-3, rng.uniform(-1, 1) * 1e-3],
                              [rng.uniform(-1, 1) * 2e-8, rng.uniform(-1, 1) * 2e-8]])
                flist.append(BiasField.linear(
                    [rng.uniform(-100, 100), np.deg2rad(rng.uniform(-0.2, 0.2))], g,
                    radars.sites[i]))
            else:
                flist.append(BiasField.smooth(rng, center=np.zeros(2), scale=region,
                                              range_amplitude=150.0,
                                              azimuth_amplitude=np.deg2rad(0.3)))
    else:
        flist = list(fields)
    paths = fly_paths(rng, n_aircraft, duration, region=region, turn_rate=turn_rate)
    plots, xs, fs = simulate_plots(rng, radars, paths, flist, periods=periods)
    return RadarNetworkScenario(plots, radars, flist, paths, xs, fs)
