"""Several surveillance radars observing aircraft, with position-dependent bias fields
(paper 001, (1)), in 2-D (one flat plane, :func:`fly_paths`) or exact 3-D
(:func:`fly_paths3d`: geodetic radar sites with their heights, aircraft at 3-12 km
flying levels, climbs, descents and holding patterns; each radar measures the slant range
and the azimuth from its own north, through ECEF with pymap3d).

Each radar's beam turns clockwise with its own period and phase; a plot is produced when
the beam crosses the aircraft, so reports are asynchronous (no two radars see an object at
the same instant, as the paper assumes). The plot is the true polar position plus the
radar's bias field f_i(x) plus Gaussian polar noise (σ_range, σ_azimuth); f_i is a
function of the position x on the common plane (in 3-D the East-North of the target's
footprint in the ENU frame of the origin). In 3-D the plots carry the TRUE target height
(m above the WGS-84 ellipsoid: what ADS-B or a corrected flight level gives), a radar
sees a target only above its geometric horizon (straight line of sight clear of a sphere
of radius 6371 km), below a 40° cone of silence and within ``max_range`` of slant
range. Aircraft fly piecewise-straight paths joined by constant-rate turns. Everything is seeded.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield import (
    AircraftPaths,
    BiasField,
    PlotTable,
    RadarSet,
    shift_from_bias,
    to_polar,
    wrap_angle,
)
from optmodels.biasfield import geometry3d as g3
from optmodels.core import FloatArray, ProblemError, as_finite_array, as_positive

__all__ = [
    "AircraftPaths",
    "RadarNetworkScenario",
    "fly_paths",
    "fly_paths3d",
    "grid_sites",
    "line_sites",
    "radar_network",
    "ring_sites",
    "simulate_plots",
]

#: Default network: four radars on a ~200 km square, typical en-route accuracy.
#: Default azimuth noise, 0.08° (rad).
SIGMA_AZIMUTH = float(np.deg2rad(0.08))
DEFAULT_SITES = np.array([[-90e3, -60e3], [100e3, -70e3], [80e3, 110e3], [-70e3, 90e3]])
#: Default common origin of the 3-D network: lat (deg), lon (deg), h (m above WGS-84).
DEFAULT_ORIGIN = np.array([55.0, 83.0, 150.0])
#: Default antenna heights of the 3-D sites (m above the ellipsoid), cycled over the radars.
DEFAULT_SITE_HEIGHTS = np.array([180.0, 420.0, 260.0, 610.0])
#: Mean earth radius (m) of the line-of-sight test.
EARTH_RADIUS = 6371e3
#: Cone of silence of the 3-D simulator: no plots above this elevation (rad), 40°.
MAX_ELEVATION = float(np.deg2rad(40.0))


def _heading_profile(
    rng: np.random.Generator, nt: int, dt: float, turn_rate: tuple[float, float], holding: float
) -> FloatArray:
    """Turn rate (rad/s) per step: legs of 2-10 min joined by 20-90 s turns; with
    probability ``holding`` one holding pattern (a racetrack: two 180° rate-one turns of
    3°/s joined by 1-min legs, flown 1-3 times) after the first leg."""
    rate = np.zeros(nt)
    k = 0
    first = True
    while k < nt:
        leg = int(rng.uniform(120, 600) / dt)
        turn = int(rng.uniform(20, 90) / dt)
        rate[k + leg : k + leg + turn] = np.deg2rad(rng.uniform(*turn_rate)) * rng.choice([-1, 1])
        k += leg + turn
        if first and rng.uniform() < holding:
            side = rng.choice([-1, 1])
            half, straight = int(60 / dt), int(60 / dt)
            for _ in range(int(rng.integers(1, 4))):
                for _ in range(2):
                    rate[k : k + half] = side * np.deg2rad(3.0)
                    k += half + straight
        first = False
    return rate


def _height_profile(
    rng: np.random.Generator,
    nt: int,
    dt: float,
    levels: tuple[float, float],
    vertical_rate: tuple[float, float],
) -> FloatArray:
    """Heights (m) per step: a level held 2-10 min, then a climb or descent at 5-15 m/s
    (``vertical_rate``) to a new level drawn in ``levels``; repeated."""
    h = np.empty(nt)
    cur = rng.uniform(*levels)
    k = 0
    while k < nt:
        hold = int(rng.uniform(120, 600) / dt)
        h[k : k + hold] = cur
        k += hold
        new = rng.uniform(*levels)
        rate = rng.uniform(*vertical_rate)
        n = max(int(np.ceil(abs(new - cur) / (rate * dt))), 1)
        ramp = cur + (new - cur) * np.arange(1, n + 1) / n
        h[k : k + n] = ramp[: max(0, min(n, nt - k))]
        k += n
        cur = new
    return h


def fly_paths(
    rng: np.random.Generator,
    n_aircraft: int,
    duration: float,
    *,
    region: float = 150e3,
    speed: tuple[float, float] = (150.0, 250.0),
    turn_rate: tuple[float, float] = (0.3, 1.0),
    dt: float = 1.0,
) -> AircraftPaths:
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
            rate[k + leg : k + leg + turn] = np.deg2rad(rng.uniform(*turn_rate)) * rng.choice(
                [-1, 1]
            )
            k += leg + turn
        psi = heading + np.cumsum(rate) * dt
        vel = v * np.column_stack([np.sin(psi), np.cos(psi)])  # heading clockwise from North
        p0 = rng.uniform(-region, region, 2)
        pos[a] = p0 + np.cumsum(vel, axis=0) * dt - vel[0] * dt
        active[a] = (times >= start) & (times <= stop)
    return AircraftPaths(times, pos, active)


def fly_paths3d(
    rng: np.random.Generator,
    n_aircraft: int,
    duration: float,
    *,
    origin: ArrayLike = DEFAULT_ORIGIN,
    region: float = 150e3,
    speed: tuple[float, float] = (150.0, 250.0),
    turn_rate: tuple[float, float] = (0.3, 1.0),
    levels: tuple[float, float] = (3e3, 12e3),
    vertical_rate: tuple[float, float] = (5.0, 15.0),
    holding: float = 0.2,
    dt: float = 1.0,
) -> AircraftPaths:
    """3-D paths, each aircraft over its own span (:class:`AircraftPaths` per aircraft):
    entering at random times and plane positions in a square of half-side ``region`` (m)
    around ``origin`` (lat deg, lon deg, h m), flying the horizontal legs and turns of
    :func:`fly_paths` (speed on the common plane, m/s), levels in ``levels`` (m above the
    WGS-84 ellipsoid) joined by climbs and descents at ``vertical_rate`` (m/s), and with
    probability ``holding`` a holding pattern. Latitude and longitude by the exact inverse
    of the common plane."""
    org = g3.site_geodetic("scenarios.fly_paths3d origin", origin)
    times_all = np.arange(0.0, float(duration) + dt, dt)
    nt = times_all.size
    ts: list[ArrayLike] = []
    ens: list[ArrayLike] = []
    hs: list[ArrayLike] = []
    for _ in range(n_aircraft):
        start = rng.uniform(0.0, 0.3 * duration)
        stop = min(duration, start + rng.uniform(0.4, 1.0) * duration)
        heading = rng.uniform(-np.pi, np.pi)
        v = rng.uniform(*speed)
        psi = heading + np.cumsum(_heading_profile(rng, nt, dt, turn_rate, holding)) * dt
        vel = v * np.column_stack([np.sin(psi), np.cos(psi)])  # heading clockwise from North
        p0 = rng.uniform(-region, region, 2)
        pos = p0 + np.cumsum(vel, axis=0) * dt - vel[0] * dt
        h = _height_profile(rng, nt, dt, levels, vertical_rate)
        on = (times_all >= start) & (times_all <= stop)
        ts.append(times_all[on])
        ens.append(pos[on])
        hs.append(h[on])
    return AircraftPaths.from_plane(ts, ens, hs, org)


def _time_ordered(rows: list[tuple[FloatArray, ...]]) -> list[FloatArray]:
    """The per-(radar, aircraft) column tuples of a simulation joined and sorted by plot
    time (the first column), stably."""
    if not rows:
        raise ProblemError("radars: no aircraft within any radar's range")
    cols = [np.concatenate(c) for c in zip(*rows, strict=True)]
    order = np.argsort(cols[0], kind="stable")
    return [c[order] for c in cols]


def _visible(site: FloatArray, slant: FloatArray, h: FloatArray) -> np.ndarray:
    """Straight line of sight from a site (lat, lon, h) to targets at slant range and
    height h clears a sphere of radius :data:`EARTH_RADIUS` (no refraction), and the
    target is below the cone of silence (elevation ≤ :data:`MAX_ELEVATION`)."""
    rs, rt = EARTH_RADIUS + site[2], EARTH_RADIUS + h
    with np.errstate(invalid="ignore", divide="ignore"):
        sin_el = (rt**2 - rs**2 - slant**2) / (2.0 * slant * rs)
    foot = -rs * sin_el  # distance along the ray to the point closest to the centre
    lowest = np.where(
        (sin_el < 0) & (foot < slant),
        rs * np.sqrt(np.clip(1 - sin_el**2, 0, 1)),
        np.minimum(rs, rt),
    )
    return (lowest > EARTH_RADIUS) & (sin_el <= np.sin(MAX_ELEVATION))


def _simulate_plots3d(
    rng: np.random.Generator,
    radars: RadarSet,
    paths: AircraftPaths,
    fields: Sequence[BiasField],
    per: FloatArray,
    phase: FloatArray,
) -> tuple[PlotTable, FloatArray, FloatArray]:
    rows: list[tuple[FloatArray, ...]] = []
    geo_sites, origin = radars.geodetic, radars.origin
    assert geo_sites is not None and origin is not None  # a 3-D radar set has both
    for i in range(radars.m):
        for a in range(len(paths)):
            t, _, geo = paths.track(a)
            if t.size < 2 or geo is None:
                continue
            _, az_all = g3.measure(geo_sites[i], geo[:, 0], geo[:, 1], geo[:, 2])
            psi = (phase[i] + 2 * np.pi * t / per[i] - az_all) / (2 * np.pi)
            psi = psi[0] + np.cumsum(
                np.concatenate([[0.0], wrap_angle(2 * np.pi * np.diff(psi)) / (2 * np.pi)])
            )
            k = np.flatnonzero(np.floor(psi[1:]) > np.floor(psi[:-1]))
            if k.size == 0:
                continue
            frac = (np.floor(psi[k + 1]) - psi[k]) / (psi[k + 1] - psi[k])
            tk = t[k] + frac * (t[k + 1] - t[k])
            gk = geo[k] + frac[:, None] * (geo[k + 1] - geo[k])
            xk = g3.common_plane(gk[:, 0], gk[:, 1], origin)
            rk, azk = g3.measure(geo_sites[i], gk[:, 0], gk[:, 1], gk[:, 2])
            f = fields[i](xk)
            noise = rng.normal(size=(tk.size, 2)) * [radars.sigma_range[i], radars.sigma_azimuth[i]]
            meas = np.column_stack([rk, azk]) + f + noise
            meas[:, 0] = np.abs(meas[:, 0])
            meas[:, 1] = wrap_angle(meas[:, 1])
            seen = (meas[:, 0] <= radars.max_range[i]) & _visible(geo_sites[i], rk, gk[:, 2])
            if not seen.any():
                continue
            rows.append(
                (
                    tk[seen],
                    np.full(int(seen.sum()), i),
                    meas[seen, 0],
                    meas[seen, 1],
                    np.full(int(seen.sum()), a),
                    xk[seen],
                    f[seen],
                    gk[seen, 2],
                )
            )
    cols = _time_ordered(rows)
    plots = PlotTable(
        cols[0], cols[1].astype(np.int64), cols[2], cols[3], cols[4].astype(np.int64), cols[7]
    )
    return plots, cols[5], cols[6]


def simulate_plots(
    rng: np.random.Generator,
    radars: RadarSet,
    paths: AircraftPaths,
    fields: Sequence[BiasField],
    *,
    periods: ArrayLike | None = None,
) -> tuple[PlotTable, FloatArray, FloatArray]:
    """Plots of every radar on every aircraft, and the truth at each plot: true position
    (n, 2) and true polar bias f_i(x) (n, 2).

    The beam of radar i points at φ_i + 2πt/T_i (clockwise from North); the relative
    phase ψ(t) = (φ_i + 2πt/T_i − α_i(x(t)))/2π crosses an integer once per scan, and the
    crossing time (linear interpolation on the path grid, which the 1 s grid resolves for
    periods ≥ 4 s) is the plot time.

    3-D (``radars.is_3d``; ``paths`` with geodetic positions, e.g. :func:`fly_paths3d`):
    the azimuth is each radar's own (clockwise from its north), the measured range the
    slant range, both exact (:func:`~optmodels.biasfield.geometry3d.measure`); the truth
    position at a plot is interpolated linearly in latitude, longitude and height between
    path samples, and the plots carry that true height. Plots below a radar's horizon are
    not produced.
    """
    m = radars.m
    if len(fields) != m:
        raise ProblemError(f"fields: need one bias field per radar ({m}), got {len(fields)}")
    per = np.asarray(periods, dtype=float) if periods is not None else rng.uniform(4.0, 12.0, m)
    per = np.broadcast_to(per, (m,))
    if np.any(per < 4.0 * paths.sample_step()):
        raise ProblemError("periods: need scan periods of at least 4 path steps")
    phase = rng.uniform(-np.pi, np.pi, m)
    if radars.is_3d:
        if not paths.is_3d:
            raise ProblemError(
                "paths: a 3-D radar set needs 3-D paths (geodetic positions: "
                "fly_paths3d or AircraftPaths.from_reports)"
            )
        return _simulate_plots3d(rng, radars, paths, fields, per, phase)
    sites = radars.sites
    assert sites is not None  # RadarSet always holds its plane sites
    rows: list[tuple[FloatArray, ...]] = []
    for i in range(m):
        for a in range(paths.positions.shape[0]):
            on = paths.active[a]
            t, p = paths.times[on], paths.positions[a, on]
            if t.size < 2:
                continue
            pol = to_polar(p, sites[i])
            psi = (phase[i] + 2 * np.pi * t / per[i] - pol[:, 1]) / (2 * np.pi)
            psi = psi[0] + np.cumsum(
                np.concatenate([[0.0], wrap_angle(2 * np.pi * np.diff(psi)) / (2 * np.pi)])
            )
            k = np.flatnonzero(np.floor(psi[1:]) > np.floor(psi[:-1]))
            frac = (np.floor(psi[k + 1]) - psi[k]) / (psi[k + 1] - psi[k])
            tk = t[k] + frac * (t[k + 1] - t[k])
            xk = p[k] + frac[:, None] * (p[k + 1] - p[k])
            pk = to_polar(xk, sites[i])
            f = fields[i](xk)
            noise = rng.normal(size=pk.shape) * [radars.sigma_range[i], radars.sigma_azimuth[i]]
            meas = pk + f + noise
            meas[:, 0] = np.abs(meas[:, 0])
            meas[:, 1] = wrap_angle(meas[:, 1])
            seen = meas[:, 0] <= radars.max_range[i]  # the radar reports within its range
            if not seen.any():
                continue
            tk, xk, f, meas = tk[seen], xk[seen], f[seen], meas[seen]
            rows.append(
                (tk, np.full(tk.size, i), meas[:, 0], meas[:, 1], np.full(tk.size, a), xk, f)
            )
    cols = _time_ordered(rows)
    plots = PlotTable(cols[0], cols[1].astype(np.int64), cols[2], cols[3], cols[4].astype(np.int64))
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

    def adsb_positions(self, seed: int | np.random.Generator, sigma: float = 10.0) -> FloatArray:
        """ADS-B positions of the aircraft at each plot time (n, 2) (m, common plane): the
        true position plus independent N(0, σ²) errors per axis and per report, ``sigma``
        (m, 1σ per horizontal axis; the default 10 m gives a 95 % radial error of 24 m,
        within NACp 9's bound EPU < 30 m). Drawn from its own ``seed`` (the scenario's
        random streams are left as they are). White per report: real ADS-B errors are
        correlated over minutes, which makes the referee's per-area means noisier than its
        χ² says (docs/formulations.md)."""
        sig = as_positive(
            "scenarios.RadarNetworkScenario.adsb_positions sigma (m)", sigma, allow_zero=True
        )
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        return self.true_position + sig * rng.normal(size=self.true_position.shape)

    def true_shift(self) -> FloatArray:
        """Shifts s_i(x) on the common plane at each plot (n, 2) (3-D: exact, at the
        plot's true height)."""
        out = np.empty_like(self.true_position)
        r, height = self.radars, self.plots.height
        for i in range(r.m):
            sel = self.plots.radar == i
            if r.is_3d:
                # a 3-D scenario: geodetic sites, the origin, the plots' true heights
                assert r.geodetic is not None and r.origin is not None and height is not None
                out[sel] = g3.shift_from_bias3d(
                    self.true_position[sel],
                    height[sel],
                    r.geodetic[i],
                    r.origin,
                    self.true_bias[sel],
                )
            else:
                assert r.sites is not None  # RadarSet always holds its plane sites
                out[sel] = shift_from_bias(self.true_position[sel], r.sites[i], self.true_bias[sel])
        return out


FieldKind = Literal["zero", "constant", "linear", "smooth"]


# ----------------------------------------------------------------------------- networks
# Sites for networks where no area is seen by every radar (issue 24): pass them as
# ``radar_network(..., sites=ring_sites(6, 180e3), max_range=150e3, region=...)``.
# How such a scenario differs from real traffic: the aircraft enter at uniform random
# places and times in a square and fly random legs and turns (no airways, no terminal
# areas, no dense flows between airports), every aircraft is seen by every radar that
# has it in range and above its horizon with probability 1 per scan (no missed plots,
# no clutter, no multipath, no beam-shape or cone-of-silence shadows beyond the 40°
# cone), the heights are exact, and each radar's bias field is a smooth function of
# the position on the common plane (no height dependence, no time drift).
def ring_sites(m: int, radius: float) -> FloatArray:
    """(m, 2) East-North (m) of ``m`` sites evenly on a circle of ``radius`` (m) about the
    origin: with a range below ``radius`` the centre is seen by none, and with a range
    between half the chord 2·radius·sin(π/m) and radius each area by two or three."""
    a = 2 * np.pi * np.arange(m) / m
    return float(radius) * np.column_stack([np.sin(a), np.cos(a)])


def line_sites(m: int, spacing: float) -> FloatArray:
    """(m, 2) ``m`` sites on the East axis, ``spacing`` (m) apart, centred on the origin
    (a range below ``spacing`` leaves pairwise overlaps only)."""
    x = (np.arange(m) - (m - 1) / 2) * float(spacing)
    return np.column_stack([x, np.zeros(m)])


def grid_sites(
    rows: int,
    cols: int,
    spacing: float,
    *,
    jitter: float = 0.0,
    seed: int | np.random.Generator = 0,
) -> FloatArray:
    """(rows·cols, 2) sites on a square grid ``spacing`` (m) apart about the origin,
    each moved by a uniform ±``jitter`` (m) per axis (a national network)."""
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    gx, gy = np.meshgrid(
        (np.arange(cols) - (cols - 1) / 2) * float(spacing),
        (np.arange(rows) - (rows - 1) / 2) * float(spacing),
    )
    s = np.column_stack([gx.ravel(), gy.ravel()])
    return s + rng.uniform(-jitter, jitter, s.shape) if jitter > 0 else s


def radar_network(
    seed: int | np.random.Generator,
    *,
    n_aircraft: int = 30,
    duration: float = 1800.0,
    sites: ArrayLike | None = None,
    fields: FieldKind | Sequence[BiasField] = "smooth",
    sigma_range: float | ArrayLike = 60.0,
    sigma_azimuth: float | ArrayLike = SIGMA_AZIMUTH,
    max_range: float | ArrayLike = 250e3,
    periods: ArrayLike | None = None,
    region: float = 150e3,
    turn_rate: tuple[float, float] = (0.3, 1.0),
    geometry: Literal["2d", "3d"] = "2d",
    origin: ArrayLike | None = None,
    site_heights: ArrayLike | None = None,
    levels: tuple[float, float] = (3e3, 12e3),
    holding: float = 0.2,
) -> RadarNetworkScenario:
    """A seeded radar network scenario.

    ``fields``: ``"zero"``; ``"constant"`` (an azimuth bias of ±0.1-0.3° per radar, no range
    bias: the parametric model (2)); ``"linear"``; ``"smooth"`` (a constant plus Gaussian
    bumps: range ±150 m, azimuth ±0.3°); or a list of :class:`BiasField`, one per radar.

    ``geometry="3d"``: ``sites`` (m, 2) are the East-North of the sites on the common plane
    of ``origin`` (lat deg, lon deg, h m; default :data:`DEFAULT_ORIGIN`), at
    ``site_heights`` (m above the ellipsoid; default :data:`DEFAULT_SITE_HEIGHTS`); the
    radar set is geodetic (slant ranges, own-north azimuths), the aircraft fly
    :func:`fly_paths3d` at ``levels`` (m) with holding patterns (probability ``holding``)
    and the plots carry the true heights.
    """
    from optmodels.core import as_choice

    is_3d = as_choice("scenarios.radar_network geometry", geometry, ("2d", "3d")) == "3d"
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    s = DEFAULT_SITES if sites is None else as_finite_array("sites", sites, ndim=2)
    m = s.shape[0] if s.ndim == 2 else 0
    args = (
        np.broadcast_to(np.asarray(sigma_range, float), (m,)),
        np.broadcast_to(np.asarray(sigma_azimuth, float), (m,)),
        np.broadcast_to(np.asarray(max_range, float), (m,)),
    )
    if is_3d:
        org = g3.site_geodetic(
            "scenarios.radar_network origin", DEFAULT_ORIGIN if origin is None else origin
        )
        hs = (
            np.resize(DEFAULT_SITE_HEIGHTS, m)
            if site_heights is None
            else np.broadcast_to(
                as_finite_array(
                    "scenarios.radar_network site_heights (m)", site_heights, ndim=(0, 1)
                ),
                (m,),
            )
        )
        if s.ndim != 2 or s.shape[1] != 2:
            raise ProblemError(f"sites: expected (m, 2) East-North (m), got {s.shape}")
        lat, lon = g3.plane_to_geodetic(s, org)
        radars = RadarSet(None, *args, geodetic=np.column_stack([lat, lon, hs]), origin=org)
    else:
        radars = RadarSet(s, *args)
    plane_sites = radars.sites
    assert plane_sites is not None  # RadarSet always holds its plane sites
    if isinstance(fields, str):
        kinds = ("zero", "constant", "linear", "smooth")
        if fields not in kinds:
            raise ProblemError(
                f"fields: expected one of {kinds} or a list of BiasField, got {fields!r}"
            )
        flist: list[BiasField] = []
        for i in range(m):
            if fields == "zero":
                flist.append(BiasField.constant(0.0, 0.0))
            elif fields == "constant":
                flist.append(
                    BiasField.constant(0.0, np.deg2rad(rng.uniform(0.1, 0.3)) * rng.choice([-1, 1]))
                )
            elif fields == "linear":
                g = np.array(
                    [
                        [rng.uniform(-1, 1) * 1e-3, rng.uniform(-1, 1) * 1e-3],
                        [rng.uniform(-1, 1) * 2e-8, rng.uniform(-1, 1) * 2e-8],
                    ]
                )
                flist.append(
                    BiasField.linear(
                        [rng.uniform(-100, 100), np.deg2rad(rng.uniform(-0.2, 0.2))],
                        g,
                        plane_sites[i],
                    )
                )
            else:
                flist.append(
                    BiasField.smooth(
                        rng,
                        center=np.zeros(2),
                        scale=region,
                        range_amplitude=150.0,
                        azimuth_amplitude=np.deg2rad(0.3),
                    )
                )
    else:
        flist = list(fields)
    if is_3d:
        assert radars.origin is not None  # a geodetic radar set has its origin
        paths = fly_paths3d(
            rng,
            n_aircraft,
            duration,
            origin=radars.origin,
            region=region,
            turn_rate=turn_rate,
            levels=levels,
            holding=holding,
        )
    else:
        paths = fly_paths(rng, n_aircraft, duration, region=region, turn_rate=turn_rate)
    plots, xs, fs = simulate_plots(rng, radars, paths, flist, periods=periods)
    return RadarNetworkScenario(plots, radars, flist, paths, xs, fs)
