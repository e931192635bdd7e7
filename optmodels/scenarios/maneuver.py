"""Targets maneuvering in a plane: the example of paper 000 and the comparison settings.

Every generator takes a seed (or a ``numpy.random.Generator``) and returns the truth with
the measurements, so that errors can be computed against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optmodels import seeds
from optmodels.core import (
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_number,
    as_positive,
)
from optmodels.plane.radar import radar_covariances as _plane_radar_covariances

__all__ = [
    "PAPER_RADIUS",
    "ManeuverScenario",
    "ManeuverTrack",
    "climb_turn_track",
    "paper_plane_example",
    "radar_covariances",
    "radar_plane",
    "two_source_plane",
]

#: Radius (m) of the turn in paper 000's example, which the paper does not give.
#: 1130 m minimises the Cramér–Rao bound on the normal angle after 10 s over the radius
#: (the best-determined plane that 10 s of a 500 m/s turn can give: 0.70 of the circle,
#: 22.5 g). Its RMS angle bound is 1.64 mrad, so the *mean* angle error is about
#: 0.886 x 1.64 = 1.45 mrad -- the paper's 1.4 mrad. No radius or phase brings the offset
#: bound below 3.3 m, so the paper's 2 m offset error is a single run's reading
#: (``docs/formulations.md``; ``optmodels demo plane`` tabulates the bound against radius).
PAPER_RADIUS = 1130.0


@dataclass(frozen=True)
class ManeuverScenario:
    """Measurements of a target on a known plane.

    Attributes
    ----------
    times : (N,) s; truth : (N, 3) true positions (m); points : (N, 3) measurements;
    cov : (3, 3) or (N, 3, 3) error covariances; alpha2 : (N,) or None, the factors of
    (1.4) when ``cov`` is (3, 3); normal, offset : the true plane (offset >= 0).
    """

    times: FloatArray
    truth: FloatArray
    points: FloatArray
    cov: FloatArray
    alpha2: FloatArray | None
    normal: FloatArray
    offset: float


def _rng(seed: int | np.random.Generator, where: str = "scenarios") -> np.random.Generator:
    """A Generator as given, or seeded from a whole number >= 0 (or a sequence of them)
    (:func:`optmodels.seeds.as_generator`)."""
    return seeds.as_generator(f"{where} seed", seed)


def paper_plane_example(
    seed: int | np.random.Generator = 0,
    *,
    radius: float = PAPER_RADIUS,
    speed: float = 500.0,
    center_distance: float = 5000.0,
    elevation_deg: float = 45.0,
    sigma2: float = 625.0,
    rate_hz: float = 100.0,
    duration: float = 10.0,
    phase: float = 0.0,
) -> ManeuverScenario:
    """Paper 000's example: a circle at constant speed in the vertical plane OXZ.

    Centre :math:`S = (D\\cos\\varepsilon, 0, D\\sin\\varepsilon)`, D = 5000 m,
    ε = 45°, speed 500 m/s, i.i.d. errors of variance 625 m² per axis, 100 Hz for 10 s
    (times 0.01 ... 10 s, N = 1000). True plane ``n = (0, 1, 0)``, ``a = 0``. ``phase``
    (rad) is the position on the circle at t = 0, measured in the x-z plane from +x.
    """
    w = "scenarios.paper_plane_example"
    radius = as_positive(f"{w} radius", radius)
    speed = as_positive(f"{w} speed", speed)
    center_distance = as_number(f"{w} center_distance", center_distance, low=0.0)
    elevation_deg = as_number(f"{w} elevation_deg", elevation_deg, low=-90.0, high=90.0)
    sigma2 = as_positive(f"{w} sigma2", sigma2)
    rate_hz = as_positive(f"{w} rate_hz", rate_hz)
    duration = as_positive(f"{w} duration", duration)
    phase = as_number(f"{w} phase", phase)
    if round(rate_hz * duration) < 3 or rate_hz * duration > 1e8:
        raise ProblemError(
            f"{w} rate_hz, duration: {rate_hz:g} Hz for {duration:g} s gives "
            f"{round(rate_hz * duration)} samples; need 3 ... 1e8"
        )
    rng = _rng(seed, w)
    eps = np.deg2rad(elevation_deg)
    centre = np.array([center_distance * np.cos(eps), 0.0, center_distance * np.sin(eps)])
    n = round(rate_hz * duration)
    times = np.arange(1, n + 1) / rate_hz
    ang = phase + speed / radius * times
    truth = centre + radius * np.column_stack([np.cos(ang), np.zeros(n), np.sin(ang)])
    cov = sigma2 * np.eye(3)
    points = truth + rng.normal(scale=np.sqrt(sigma2), size=truth.shape)
    return ManeuverScenario(
        times=times,
        truth=truth,
        points=points,
        cov=cov,
        alpha2=np.ones(n),
        normal=np.array([0.0, 1.0, 0.0]),
        offset=0.0,
    )


def _plane_patch(
    rng: np.random.Generator,
    n: int,
    normal: FloatArray,
    offset: float,
    extent: float,
    centre_in_plane: FloatArray | None = None,
) -> FloatArray:
    """N true points uniformly on a square patch of the plane ⟨normal, x⟩ = offset."""
    nrm = normal / np.linalg.norm(normal)
    _, _, vt = np.linalg.svd(nrm[None, :])
    uv = rng.uniform(-extent / 2, extent / 2, size=(n, 2))
    base = offset * nrm + (0 if centre_in_plane is None else centre_in_plane)
    return base + uv @ vt[1:]


def two_source_plane(
    n: int,
    seed: int | np.random.Generator = 0,
    *,
    sigma: float = 10.0,
    ratio2: float = 100.0,
    extent: float = 2000.0,
    tilt_deg: float = 30.0,
    offset: float = 1000.0,
) -> ManeuverScenario:
    """Setting (a) of the comparison: two sources whose error variances differ by
    ``ratio2`` (α² ∈ {1, ratio2}, the motivation of (1.4)); isotropic errors of std
    ``sigma`` (m) for the good source on a square patch ``extent`` (m) wide, the plane
    tilted by ``tilt_deg`` from horizontal at ``offset`` (m). Points alternate between the
    sources."""
    w = "scenarios.two_source_plane"
    n = as_count(f"{w} n", n, minimum=3, maximum=10**8)
    sigma = as_positive(f"{w} sigma", sigma)
    ratio2 = as_positive(f"{w} ratio2", ratio2)
    extent = as_positive(f"{w} extent", extent)
    tilt_deg = as_number(f"{w} tilt_deg", tilt_deg)
    offset = as_number(f"{w} offset", offset)
    rng = _rng(seed, w)
    t = np.deg2rad(tilt_deg)
    normal = np.array([np.sin(t), 0.0, np.cos(t)])
    truth = _plane_patch(rng, n, normal, offset, extent)
    alpha2 = np.where(np.arange(n) % 2 == 0, 1.0, ratio2)
    cov = sigma**2 * np.eye(3)
    points = truth + rng.normal(size=(n, 3)) * (sigma * np.sqrt(alpha2))[:, None]
    return ManeuverScenario(
        times=np.arange(n, dtype=float),
        truth=truth,
        points=points,
        cov=cov,
        alpha2=alpha2,
        normal=normal,
        offset=offset,
    )


def radar_covariances(
    points: FloatArray,
    site: FloatArray,
    sigma_range: float,
    sigma_az: float,
    sigma_el: float,
) -> FloatArray:
    """Cartesian error covariances (N, 3, 3) of a radar at ``site`` measuring range,
    azimuth and elevation with independent errors (m, rad, rad; azimuth clockwise from
    north, ENU axes). Moved to :func:`optmodels.plane.radar.radar_covariances` (the
    problem's API, where its frame and first-order error are documented); this is that
    function under its former argument names."""
    return _plane_radar_covariances(points, site, sigma_range, sigma_az, sigma_el)


def radar_plane(
    n: int,
    seed: int | np.random.Generator = 0,
    *,
    sigma_range: float = 10.0,
    sigma_angle: float = 2e-3,
    r_min: float = 20e3,
    r_max: float = 50e3,
    geometry: str = "broadside",
) -> ManeuverScenario:
    """Setting (b) of the comparison: one radar at the origin, anisotropic errors
    (σ_range = 10 m, σ_az = σ_el = 2 mrad: 40-100 m across the beam at 20-50 km).

    ``geometry="broadside"``: the plane's normal points along the line of sight (the
    plane faces the radar, so its normal is measured by the precise range).
    ``geometry="edge-on"``: the radar's line of sight lies in the plane, so the normal
    is measured only by the imprecise angles.
    """
    w = "scenarios.radar_plane"
    n = as_count(f"{w} n", n, minimum=3, maximum=10**8)
    sigma_range = as_positive(f"{w} sigma_range", sigma_range)
    sigma_angle = as_positive(f"{w} sigma_angle", sigma_angle)
    r_min = as_positive(f"{w} r_min", r_min)
    r_max = as_number(f"{w} r_max", r_max, low=r_min, low_open=True)
    geometry = as_choice(f"{w} geometry", geometry, ("broadside", "edge-on"))
    rng = _rng(seed, w)
    rc = 0.5 * (r_min + r_max)
    span = r_max - r_min
    centre = np.array([0.0, rc, 3000.0])
    los = centre / np.linalg.norm(centre)
    if geometry == "broadside":
        normal = los
        truth = _plane_patch(
            rng, n, normal, float(normal @ centre), span, centre - (normal @ centre) * normal
        )
    elif geometry == "edge-on":
        normal = np.array([1.0, 0.0, 0.0])
        _, _, vt = np.linalg.svd(normal[None, :])
        uv = rng.uniform(-span / 2, span / 2, size=(n, 2))
        truth = centre + uv @ vt[1:]
    else:
        raise ProblemError(f"geometry: expected 'broadside' or 'edge-on', got {geometry!r}")
    cov = radar_covariances(truth, np.zeros(3), sigma_range, sigma_angle, sigma_angle)
    chol = np.linalg.cholesky(cov)
    points = truth + (chol @ rng.normal(size=(n, 3, 1)))[..., 0]
    offset = float(normal @ truth[0])
    if offset < 0:
        normal, offset = -normal, -offset
    return ManeuverScenario(
        times=np.arange(n, dtype=float),
        truth=truth,
        points=points,
        cov=cov,
        alpha2=None,
        normal=normal,
        offset=offset,
    )


@dataclass(frozen=True)
class ManeuverTrack:
    """A straight climb, then a climbing turn, then a level turn, seen by one radar.

    Attributes
    ----------
    times : (N,) s; truth, points : (N, 3) true and measured positions, m, in the radar's
    local flat ENU frame; cov : (N, 3, 3) the radar covariances
    (:func:`optmodels.plane.radar.radar_covariances` at the true points), m²;
    site : (3,) the radar, m; transitions : (2,) s, the true times the climbing turn and
    the level turn begin; segment : (N,) int, 0 climb, 1 climbing turn, 2 level turn;
    normals : (3, 3) unit normal of each segment's plane (row 0 NaN: a straight line has
    no plane), offsets : (3,) m (NaN for the line); tilt_deg : (3,) tilt of each plane
    from the horizontal, degrees (NaN for the line).
    """

    times: FloatArray
    truth: FloatArray
    points: FloatArray
    cov: FloatArray
    site: FloatArray
    transitions: FloatArray
    segment: np.ndarray
    normals: FloatArray
    offsets: FloatArray
    tilt_deg: FloatArray


def climb_turn_track(
    seed: int | np.random.Generator = 0,
    *,
    speed: float = 150.0,
    climb_deg: float = 6.0,
    turn_rate_deg: float = 3.0,
    durations: tuple[float, float, float] = (60.0, 30.0, 60.0),
    rate_hz: float = 2.0,
    start: tuple[float, float, float] = (20e3, 25e3, 3000.0),
    heading_deg: float = 0.0,
    sigma_range: float = 30.0,
    sigma_azimuth: float = 1e-3,
    sigma_elevation: float = 1e-3,
) -> ManeuverTrack:
    """A straight climb → climbing turn → level turn at constant speed, one radar at the
    ENU origin measuring range, azimuth and elevation (issue 19's demo track).

    Segment 0 (``durations[0]`` s): a straight line climbing at ``climb_deg`` on heading
    ``heading_deg`` (clockwise from north). Segment 1: a turn to the right at
    ``turn_rate_deg`` (°/s) in the plane spanned by the climbing velocity and the
    horizontal right-hand direction: a planar manoeuvre whose plane is tilted by
    ``climb_deg`` from the horizontal; the climb rate falls from ``speed sin γ`` to
    ``speed sin γ cos(ω t)``. Segment 2: a level turn (horizontal plane through the end
    of segment 1) at the same rate, entered along the horizontal part of the
    velocity at the end of segment 1, so position is continuous and the path is planar
    in each segment (the heading is continuous; the climb rate jumps to 0 at the second transition).

    Units: m, s, m/s; angles in degrees where named ``_deg``; ``sigma_azimuth``,
    ``sigma_elevation`` in rad. Measurements: truth + N(0, D_i) with D_i the radar
    covariances at the true points (the first-order model; the polar noise itself is
    not simulated).
    """
    w = "scenarios.climb_turn_track"
    speed = as_positive(f"{w} speed (m/s)", speed)
    climb = np.deg2rad(as_number(f"{w} climb_deg", climb_deg, low=-60.0, high=60.0))
    omega = np.deg2rad(as_positive(f"{w} turn_rate_deg (deg/s)", turn_rate_deg))
    if not isinstance(durations, tuple | list) or len(durations) != 3:
        raise ProblemError(f"{w} durations: expected three durations (s), got {durations!r}")
    dur = [as_positive(f"{w} durations[{k}] (s)", v) for k, v in enumerate(durations)]
    rate_hz = as_positive(f"{w} rate_hz", rate_hz)
    p0 = as_finite_array(f"{w} start (m)", start, shape=(3,), max_abs=1e8)
    heading = np.deg2rad(as_number(f"{w} heading_deg", heading_deg))
    total = sum(dur)
    n = int(np.floor(total * rate_hz))
    if n < 10 or n > 10**7:
        raise ProblemError(f"{w} rate_hz, durations: {n} samples; need 10 ... 1e7")
    rng = _rng(seed, w)
    times = np.arange(n) / rate_hz
    hdir = np.array([np.sin(heading), np.cos(heading), 0.0])
    right = np.array([np.cos(heading), -np.sin(heading), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    v0 = np.cos(climb) * hdir + np.sin(climb) * up  # unit velocity of the climb
    t1, t2 = dur[0], dur[0] + dur[1]
    radius = speed / omega
    p1 = p0 + speed * t1 * v0
    # segment 1: circle in the plane (v0, right), turning towards `right`
    n1 = np.cross(v0, right)
    ang1 = omega * dur[1]
    p2 = p1 + radius * (np.sin(ang1) * v0 + (1 - np.cos(ang1)) * right)
    v2 = np.cos(ang1) * v0 + np.sin(ang1) * right  # unit velocity at the end of segment 1
    # segment 2: level turn, entered along the horizontal part of v2, same sense
    h2 = v2 - (v2 @ up) * up
    h2 = h2 / np.linalg.norm(h2)
    r2 = np.cross(h2, up)  # right of h2
    truth = np.empty((n, 3))
    seg = np.zeros(n, dtype=int)
    for i, t in enumerate(times):
        if t < t1:
            truth[i] = p0 + speed * t * v0
        elif t < t2:
            a = omega * (t - t1)
            truth[i] = p1 + radius * (np.sin(a) * v0 + (1 - np.cos(a)) * right)
            seg[i] = 1
        else:
            a = omega * (t - t2)
            truth[i] = p2 + radius * (np.sin(a) * h2 + (1 - np.cos(a)) * r2)
            seg[i] = 2
    site = np.zeros(3)
    cov = _plane_radar_covariances(truth, site, sigma_range, sigma_azimuth, sigma_elevation)
    chol = np.linalg.cholesky(cov)
    points = truth + (chol @ rng.normal(size=(n, 3, 1)))[..., 0]
    normals = np.full((3, 3), np.nan)
    offsets = np.full(3, np.nan)
    for k, (nv, p) in enumerate(((n1, p1), (up, p2)), start=1):
        nv = nv / np.linalg.norm(nv)
        off = float(nv @ p)
        if off < 0:
            nv, off = -nv, -off
        normals[k], offsets[k] = nv, off
    tilt = np.degrees(np.arccos(np.clip(np.abs(normals[:, 2]), 0.0, 1.0)))
    return ManeuverTrack(
        times=times,
        truth=truth,
        points=points,
        cov=cov,
        site=site,
        transitions=np.array([t1, t2]),
        segment=seg,
        normals=normals,
        offsets=offsets,
        tilt_deg=tilt,
    )
