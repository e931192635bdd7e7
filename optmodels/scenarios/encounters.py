r"""Crossing and parallel encounters of 2-4 objects seen by a 2-D radar with a finite
resolution cell (issue 18, track-level evaluation of paper 004's unresolved groups).

Frame: Cartesian (x, y) in m with the radar at ``site`` (default the origin); states in
Stone Soup's order [x, vx, y, vy] (m, m/s); time in s from the first scan.

Geometry (the scene centre c = site + (range_0, 0), so x is the radial direction there):

* ``crossing``: object k passes c + o_k x̂ at t_c (the middle scan) with velocity
  (V cos a, s_k V sin a), o_k = (k − (Q−1)/2)·separation, s_k spread evenly in [−1, 1]:
  every pair's relative velocity is cross-range (ŷ) and its offset radial (x̂), so each
  pair's closest approach is at t_c with miss distance |o_k − o_l| (radial), and the paths
  cross in the plane (X shape) — the tracks swap if the association does;
* ``parallel``: the same with s_k = 0 (one velocity): a formation at constant radial
  spacing, unresolved for the whole run when the spacing is below the range resolution.

Sensor (:class:`RadarCell`): each scan, the objects whose returns fall in one resolution
cell (|Δr| < ``range_res`` and |Δaz| < ``azimuth_res`` pairwise; groups are the connected
components of that relation) give one return at their centroid (equal weights), detected
with probability P_D per group; polar noise σ_r, σ_az on the centroid's polar coordinates;
each measurement is converted to Cartesian with its own covariance J diag(σ_r², σ_az²) Jᵀ
(J the Jacobian of (r, az) → (x, y) at the measurement). Clutter: Poisson, mean
``clutter_mean`` per scan, uniform in the box ``region`` around the scene.

Issue 29: :func:`traffic_encounter` draws pairs that look like real close encounters
(fast crossings with 1-3 merged scans, slow formations, long merges; 49 scans, the
150 m × 1.4° radar of :func:`traffic_sensor`); its docstring states how they differ from
real traffic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from optmodels.core import (
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_instance,
    as_number,
    as_positive,
    as_probability,
)

__all__ = [
    "TRAFFIC_KINDS",
    "Encounter",
    "RadarCell",
    "Scan",
    "encounter",
    "observe",
    "polar_to_cartesian",
    "traffic_encounter",
    "traffic_sensor",
]

_W = "scenarios.encounter"


@dataclass
class RadarCell:
    """A 2-D radar: ``site`` (2,) m; resolution ``range_res`` (m) and ``azimuth_res``
    (rad); noise ``sigma_range`` (m), ``sigma_azimuth`` (rad); detection probability
    ``pd``; Poisson clutter ``clutter_mean`` per scan, uniform in ``region`` (x0, x1,
    y0, y1) m (set by :func:`encounter` when None). Azimuth measured from +x towards +y."""

    range_res: float = 150.0
    azimuth_res: float = math.radians(1.0)
    sigma_range: float = 20.0
    sigma_azimuth: float = math.radians(0.1)
    pd: float = 0.9
    clutter_mean: float = 2.0
    site: FloatArray = field(default_factory=lambda: np.zeros(2))
    region: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        w = "scenarios.RadarCell"
        self.range_res = as_positive(f"{w} range_res (m)", self.range_res)
        self.azimuth_res = as_positive(f"{w} azimuth_res (rad)", self.azimuth_res)
        self.sigma_range = as_positive(f"{w} sigma_range (m)", self.sigma_range)
        self.sigma_azimuth = as_positive(f"{w} sigma_azimuth (rad)", self.sigma_azimuth)
        self.pd = as_probability(f"{w} pd", self.pd, low_open=True)
        self.clutter_mean = as_positive(f"{w} clutter_mean", self.clutter_mean, allow_zero=True)
        self.site = as_finite_array(f"{w} site (m)", self.site, shape=(2,))
        if self.region is not None:
            r = as_finite_array(f"{w} region (m)", self.region, shape=(4,))
            if not (r[1] > r[0] and r[3] > r[2]):
                raise ProblemError(f"{w} region (m): expected x0 < x1 and y0 < y1, got {r}")
            self.region = (float(r[0]), float(r[1]), float(r[2]), float(r[3]))

    @property
    def clutter_density(self) -> float:
        """Clutter spatial density λ (m⁻²) = clutter_mean / area of ``region``."""
        if self.region is None:
            raise ProblemError("scenarios.RadarCell region: not set")
        x0, x1, y0, y1 = self.region
        return max(self.clutter_mean, 1e-12) / ((x1 - x0) * (y1 - y0))

    def polar(self, xy: FloatArray) -> FloatArray:
        """(r, az) (m, rad) of Cartesian points (k, 2)."""
        d = np.atleast_2d(xy) - self.site
        return np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])])

    def groups(self, xy: FloatArray) -> list[tuple[int, ...]]:
        """The unresolved groups of the objects at ``xy`` (k, 2): connected components of
        the pairwise relation |Δr| < range_res and |Δaz| < azimuth_res."""
        pol = self.polar(xy)
        k = len(pol)
        near = (np.abs(pol[:, None, 0] - pol[None, :, 0]) < self.range_res) & (
            np.abs(_wrap(pol[:, None, 1] - pol[None, :, 1])) < self.azimuth_res
        )
        label = list(range(k))
        for i in range(k):
            for j in range(i + 1, k):
                if near[i, j]:
                    a, b = label[i], label[j]
                    label = [a if v == b else v for v in label]
        out: dict[int, list[int]] = {}
        for i, v in enumerate(label):
            out.setdefault(v, []).append(i)
        return sorted(tuple(g) for g in out.values())


def _wrap(a: FloatArray) -> FloatArray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def polar_to_cartesian(sensor: RadarCell, rng_az: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Cartesian points (k, 2) and their covariances (k, 2, 2) = J diag(σ_r², σ_az²) Jᵀ of
    polar measurements (k, 2) (m, rad), J evaluated at each measurement."""
    ra = np.atleast_2d(rng_az)
    r, az = ra[:, 0], ra[:, 1]
    c, s = np.cos(az), np.sin(az)
    xy = sensor.site + np.column_stack([r * c, r * s])
    jac = np.stack([np.stack([c, -r * s], axis=1), np.stack([s, r * c], axis=1)], axis=1)
    d = np.diag([sensor.sigma_range**2, sensor.sigma_azimuth**2])
    return xy, jac @ d @ np.swapaxes(jac, 1, 2)


@dataclass
class Scan:
    """One scan: ``time`` (s), ``measurements`` (N, 2) m, their covariances ``covs``
    (N, 2, 2) m², ``sources`` (N tuples of object indices; () for clutter), the true
    unresolved ``groups`` of the scan (detected or not)."""

    time: float
    measurements: FloatArray
    covs: FloatArray
    sources: list[tuple[int, ...]]
    groups: list[tuple[int, ...]]


@dataclass
class Encounter:
    """A simulated encounter: ``kind``, ``separation`` (m), ``truth`` (Q, T, 4) states
    [x, vx, y, vy], ``times`` (T,) s, ``scans``, ``sensor``, ``initial_covar`` (4, 4) of
    the trackers' initial states drawn in ``initial`` (Q, 4)."""

    kind: str
    separation: float
    times: FloatArray
    truth: FloatArray
    scans: list[Scan]
    sensor: RadarCell
    initial: FloatArray
    initial_covar: FloatArray

    @property
    def q(self) -> int:
        return int(self.truth.shape[0])

    @property
    def merged_scans(self) -> int:
        """Scans in which at least one group of ≥ 2 objects was unresolved."""
        return sum(any(len(g) > 1 for g in s.groups) for s in self.scans)


def observe(sensor: RadarCell, xy: FloatArray, time: float, rng: np.random.Generator) -> Scan:
    """One scan of the objects at ``xy`` (Q, 2) m (module docstring)."""
    groups = sensor.groups(xy)
    pts, sources = [], []
    for g in groups:
        if rng.random() < sensor.pd:
            pol = sensor.polar(xy[list(g)].mean(axis=0))[0]
            pts.append(pol + rng.normal(0.0, [sensor.sigma_range, sensor.sigma_azimuth]))
            sources.append(g)
    if sensor.region is None:
        raise ProblemError("scenarios.observe sensor: its clutter region is not set")
    x0, x1, y0, y1 = sensor.region
    for _ in range(int(rng.poisson(sensor.clutter_mean))):
        p = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
        pts.append(sensor.polar(p)[0] + rng.normal(0.0, [sensor.sigma_range, sensor.sigma_azimuth]))
        sources.append(())
    if pts:
        meas, covs = polar_to_cartesian(sensor, np.array(pts))
    else:
        meas, covs = np.zeros((0, 2)), np.zeros((0, 2, 2))
    order = rng.permutation(len(pts))
    return Scan(float(time), meas[order], covs[order], [sources[i] for i in order], groups)


def encounter(
    rng: np.random.Generator,
    *,
    kind: str = "crossing",
    q: int = 2,
    separation: float = 100.0,
    sensor: RadarCell | None = None,
    range_0: float = 50_000.0,
    speed: float = 250.0,
    half_angle_deg: float = 5.0,
    scans: int = 24,
    dt: float = 5.0,
    init_sigma: tuple[float, float] = (30.0, 5.0),
) -> Encounter:
    """Simulate one encounter (module docstring).

    Parameters
    ----------
    rng : seeded generator (``np.random.default_rng(seed)``).
    kind : ``"crossing"`` or ``"parallel"``.
    q : 2-4 objects.
    separation : radial miss distance of neighbours at the middle scan (m).
    sensor : the radar (default :class:`RadarCell`); its ``region`` is set to the scene
        box (± 2 km around the paths) when None.
    range_0 : range of the scene centre from the site (m).
    speed : V (m/s); ``half_angle_deg`` a: the crossing half-angle (degrees).
    scans, dt : number of scans and the scan period (s).
    init_sigma : σ of the trackers' initial position (m) and velocity (m/s) errors.
    """
    kind = as_choice(f"{_W} kind", kind, ("crossing", "parallel"))
    q = as_count(f"{_W} q", q, minimum=2, maximum=4)
    separation = as_positive(f"{_W} separation (m)", separation)
    sensor = RadarCell() if sensor is None else as_instance(f"{_W} sensor", sensor, RadarCell)
    range_0 = as_positive(f"{_W} range_0 (m)", range_0)
    speed = as_positive(f"{_W} speed (m/s)", speed)
    a = math.radians(as_number(f"{_W} half_angle_deg", half_angle_deg, low=0.0, high=45.0))
    scans = as_count(f"{_W} scans", scans, minimum=3)
    dt = as_positive(f"{_W} dt (s)", dt)
    sp, sv = (as_positive(f"{_W} init_sigma", v) for v in init_sigma)
    times = np.arange(scans, dtype=np.float64) * dt
    tc = times[scans // 2]
    centre = sensor.site + np.array([range_0, 0.0])
    offs = (np.arange(q) - (q - 1) / 2) * separation
    spread = np.linspace(-1.0, 1.0, q) if kind == "crossing" else np.zeros(q)
    truth = np.empty((q, scans, 4))
    for k in range(q):
        vx, vy = speed * math.cos(a), spread[k] * speed * math.sin(a)
        truth[k, :, 0] = centre[0] + offs[k] + vx * (times - tc)
        truth[k, :, 2] = centre[1] + vy * (times - tc)
        truth[k, :, 1], truth[k, :, 3] = vx, vy
    if sensor.region is None:
        pos = truth[:, :, [0, 2]].reshape(-1, 2)
        lo, hi = pos.min(axis=0) - 2000.0, pos.max(axis=0) + 2000.0
        sensor = RadarCell(
            sensor.range_res,
            sensor.azimuth_res,
            sensor.sigma_range,
            sensor.sigma_azimuth,
            sensor.pd,
            sensor.clutter_mean,
            sensor.site.copy(),
            (lo[0], hi[0], lo[1], hi[1]),
        )
    p0 = np.diag([sp**2, sv**2, sp**2, sv**2])
    initial = truth[:, 0, :] + rng.multivariate_normal(np.zeros(4), p0, size=q)
    obs = [observe(sensor, truth[:, t, :][:, [0, 2]], times[t], rng) for t in range(scans)]
    return Encounter(kind, separation, times, truth, obs, sensor, initial, p0)


# ----------------------------------------------------------------------------- traffic
#: The encounter kinds of :func:`traffic_encounter` (issue 29).
TRAFFIC_KINDS = ("fast_crossing", "formation", "long_merge")


def traffic_sensor() -> RadarCell:
    """The issue-29 radar: cell 150 m × 1.4°, σ 50 m / 0.1°, P_D 0.9, 2 clutter returns
    per scan in the scene box."""
    return RadarCell(
        range_res=150.0,
        azimuth_res=math.radians(1.4),
        sigma_range=50.0,
        sigma_azimuth=math.radians(0.1),
        pd=0.9,
        clutter_mean=2.0,
    )


def _pair_paths(
    rng: np.random.Generator,
    times: FloatArray,
    tc: float,
    centre: FloatArray,
    v_rel: float,
    miss: float,
    speed: float,
) -> FloatArray:
    """Two constant-velocity paths: object 0 at ``speed`` with a random heading through
    ``centre`` at ``tc``; object 1 with relative velocity of magnitude ``v_rel`` at a
    random angle, passing object 0 at the miss distance ``miss`` at ``tc``."""
    h0 = rng.uniform(0.0, 2 * math.pi)
    v0 = speed * np.array([math.cos(h0), math.sin(h0)])
    hr = rng.uniform(0.0, 2 * math.pi)
    ur = np.array([math.cos(hr), math.sin(hr)])
    v1 = v0 + v_rel * ur
    side = np.array([-ur[1], ur[0]]) * miss * (1.0 if rng.random() < 0.5 else -1.0)
    truth = np.empty((2, len(times), 4))
    for k, (p, v) in enumerate(((centre, v0), (centre + side, v1))):
        truth[k, :, 0] = p[0] + v[0] * (times - tc)
        truth[k, :, 2] = p[1] + v[1] * (times - tc)
        truth[k, :, 1], truth[k, :, 3] = v[0], v[1]
    return truth


def traffic_encounter(
    rng: np.random.Generator,
    kind: str = "fast_crossing",
    *,
    sensor: RadarCell | None = None,
    scans: int = 49,
    dt: float = 5.0,
    init_sigma: tuple[float, float] = (30.0, 5.0),
    max_tries: int = 200,
) -> Encounter:
    """A pair encounter drawn to look like real close encounters of air traffic (issue
    29), seen by :func:`traffic_sensor` (or ``sensor``) for ``scans`` scans ``dt`` apart.

    Kinds (parameters uniform; closest approach at the middle scan; the scene at a
    random azimuth and a range uniform in 20-120 km from the site; object 0's speed
    uniform in 120-250 m/s with a random heading):

    * ``"fast_crossing"``: relative speed 30-340 m/s at a random angle, miss distance
      0-300 m; redrawn (same generator) until 1-3 scans are merged;
    * ``"formation"``: the same heading, relative speed 0-3 m/s, miss distance 100-600 m
      (a formation or one aircraft following another on an airway); any number of
      merged scans;
    * ``"long_merge"``: relative speed 3-30 m/s, miss distance 0-200 m (slow overtaking,
      converging on a route); redrawn until at least 8 scans are merged.

    How this differs from real traffic: straight constant-velocity paths (no turns,
    climbs or speed changes); 2-D positions only (many real pairs in one 2-D cell are
    separated in altitude, which changes nothing for a 2-D radar but much for the
    pilots); a merged return at the members' centroid with equal weights (a real plot
    extractor weighs by amplitude and may split or drop a merged plot); P_D independent
    per scan and per group; clutter Poisson and uniform; no position jumps of the
    source (ADS-B) and no track initiation or deletion; the parameter ranges are
    plausible, not fitted to recorded traffic, and the rejection on the number of
    merged scans selects the encounter set by construction.

    Raises
    ------
    ProblemError
        Bad arguments, or no draw with the wanted number of merged scans in
        ``max_tries``.
    """
    w = "scenarios.traffic_encounter"
    kind = as_choice(f"{w} kind", kind, TRAFFIC_KINDS)
    sensor = traffic_sensor() if sensor is None else as_instance(f"{w} sensor", sensor, RadarCell)
    scans = as_count(f"{w} scans", scans, minimum=3)
    dt = as_positive(f"{w} dt (s)", dt)
    sp, sv = (as_positive(f"{w} init_sigma", v) for v in init_sigma)
    max_tries = as_count(f"{w} max_tries", max_tries, minimum=1)
    times = np.arange(scans, dtype=np.float64) * dt
    tc = float(times[scans // 2])
    for _ in range(max_tries):
        rng_0, az0 = rng.uniform(20_000.0, 120_000.0), rng.uniform(-math.pi, math.pi)
        centre = sensor.site + rng_0 * np.array([math.cos(az0), math.sin(az0)])
        speed = rng.uniform(120.0, 250.0)
        if kind == "fast_crossing":
            v_rel, miss = rng.uniform(30.0, 340.0), rng.uniform(0.0, 300.0)
        elif kind == "formation":
            v_rel, miss = rng.uniform(0.0, 3.0), rng.uniform(100.0, 600.0)
        else:
            v_rel, miss = rng.uniform(3.0, 30.0), rng.uniform(0.0, 200.0)
        truth = _pair_paths(rng, times, tc, centre, v_rel, miss, speed)
        merged = sum(
            any(len(g) > 1 for g in sensor.groups(truth[:, t][:, [0, 2]])) for t in range(scans)
        )
        if (
            (kind == "fast_crossing" and 1 <= merged <= 3)
            or kind == "formation"
            or (kind == "long_merge" and merged >= 8)
        ):
            break
    else:
        raise ProblemError(f"{w}: no {kind} draw with the wanted merged scans in {max_tries} tries")
    pos = truth[:, :, [0, 2]].reshape(-1, 2)
    lo, hi = pos.min(axis=0) - 2000.0, pos.max(axis=0) + 2000.0
    sensor = RadarCell(
        sensor.range_res,
        sensor.azimuth_res,
        sensor.sigma_range,
        sensor.sigma_azimuth,
        sensor.pd,
        sensor.clutter_mean,
        sensor.site.copy(),
        (lo[0], hi[0], lo[1], hi[1]),
    )
    p0 = np.diag([sp**2, sv**2, sp**2, sv**2])
    initial = truth[:, 0, :] + rng.multivariate_normal(np.zeros(4), p0, size=2)
    obs = [observe(sensor, truth[:, t, :][:, [0, 2]], times[t], rng) for t in range(scans)]
    return Encounter(kind, float(miss), times, truth, obs, sensor, initial, p0)
