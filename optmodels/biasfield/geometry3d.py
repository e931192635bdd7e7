r"""Exact 3-D radar geometry of paper 001 (section 1) on the WGS-84 ellipsoid.

Each radar i stands at its geodetic site (φ_i, λ_i, h_i) (latitude, longitude in degrees,
height in metres above the WGS-84 ellipsoid) and measures, in its **own** local frame
(its north, its vertical), the **slant** range r (m, the straight-line distance) and the
azimuth α (rad, clockwise from its own north, wrapped to (−π, π]) of a target at geodetic
(φ, λ, h). The conversions go through ECEF with :mod:`pymap3d` (``geodetic2aer``,
``aer2geodetic``, ``geodetic2enu``, ``enu2geodetic``), vectorised; no flat-earth step.

The common horizontal plane on which the bias field lives (the paper's plane) is the
**tangent plane of the common origin** o = (φ_o, λ_o, h_o): a target's plane position is the
East-North pair, in the local ENU frame of o, of its **footprint** (φ, λ, 0) on the
ellipsoid (:func:`common_plane`). It depends on latitude and longitude only (two aircraft
over the same ground point share it whatever their heights), it is the plane the 2-D code
already uses for sites read from latitude/longitude, and its distortion is the orthographic
one: radial scale cos(d/R) (−1.1e-3 at d = 300 km, positions within d − R sin(d/R) ≈ 110 m
of the geodesic distance from o at 300 km, 4 m at 100 km), tangential scale 1. The bias
field f_i is a function of the plane position x; a radar's polar map at a target height h
is

.. math::
    p_i(x; h) = \mathrm{aer}_i(\mathrm{geo}(x), h), \qquad
    \nabla p_i(x; h) = \partial (r, \alpha) / \partial (E, N)\big|_h,

with geo the inverse of the plane map (:func:`plane_to_geodetic`) and the Jacobian at
fixed height by the chain rule through latitude and longitude, each factor by central
differences of an exact pymap3d map (:func:`polar_jacobian3d`; steps ≈ 1 m, relative error
≈ 1e-9). :func:`locate` is p_i⁻¹: from (r, α) and the target's height it
finds the elevation that puts the target at that ellipsoidal height.
"""

from __future__ import annotations

import numpy as np
import pymap3d
from numpy.typing import ArrayLike

from optmodels.biasfield.geometry import wrap_angle
from optmodels.core import FloatArray, ProblemError, as_finite_array

__all__ = [
    "bias_from_shift3d",
    "common_plane",
    "from_polar3d",
    "locate",
    "measure",
    "plane_jacobian",
    "plane_to_geodetic",
    "polar_jacobian3d",
    "shift_from_bias3d",
    "site_geodetic",
    "to_polar3d",
]

#: Semi-major axis of WGS-84 (m): the sphere used only for starting guesses.
_A = 6378137.0
#: Newton iterations of :func:`locate` and :func:`plane_to_geodetic` (each converges to
#: < 1e-6 m in 3-4; the rest are safety).
_ITER = 8
#: Central-difference step (deg of latitude/longitude, ≈ 1 m) of the Jacobians.
_STEP_DEG = 1e-5


def site_geodetic(name: str, site: ArrayLike) -> FloatArray:
    """A geodetic point (3,): latitude (deg, |φ| < 90), longitude (deg), height (m)."""
    s = as_finite_array(name, site, shape=(3,))
    if abs(s[0]) >= 90.0 or abs(s[2]) > 1e5:
        raise ProblemError(
            f"{name}: expected (latitude deg in (−90, 90), longitude deg, "
            f"height m within ±100 km), got {s.tolist()}"
        )
    return s


def _arr(name: str, x: ArrayLike) -> FloatArray:
    return np.asarray(as_finite_array(name, x), dtype=float)


def measure(
    site: ArrayLike, lat: ArrayLike, lon: ArrayLike, h: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Slant range (m) and azimuth (rad, clockwise from the radar's own north, in (−π, π])
    of targets at geodetic (lat, lon (deg), h (m above the ellipsoid)) seen from ``site``
    (lat deg, lon deg, h m). Broadcasts over the target arrays."""
    s = site_geodetic("biasfield.measure site", site)
    az, _, rng = pymap3d.geodetic2aer(
        _arr("biasfield.measure lat", lat),
        _arr("biasfield.measure lon", lon),
        _arr("biasfield.measure h", h),
        s[0],
        s[1],
        s[2],
    )
    return np.asarray(rng, dtype=float), wrap_angle(np.deg2rad(az))


def common_plane(lat: ArrayLike, lon: ArrayLike, origin: ArrayLike) -> FloatArray:
    """Plane position (..., 2) East, North (m) of the footprint (lat, lon, 0) in the local
    ENU frame of ``origin`` (lat deg, lon deg, h m); see the module docstring."""
    o = site_geodetic("biasfield.common_plane origin", origin)
    la = _arr("biasfield.common_plane lat", lat)
    e, n, _ = pymap3d.geodetic2enu(
        la, _arr("biasfield.common_plane lon", lon), np.zeros(np.shape(la)), o[0], o[1], o[2]
    )
    return np.stack([np.asarray(e, float), np.asarray(n, float)], axis=-1)


def plane_to_geodetic(en: ArrayLike, origin: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Inverse of :func:`common_plane`: latitude, longitude (deg) of the footprint whose
    plane position is ``en`` (..., 2) (Newton on the Up coordinate along the origin's
    vertical, until the point lies on the ellipsoid to < 1e-6 m). Points farther than
    0.9 R from the origin are refused."""
    o = site_geodetic("biasfield.plane_to_geodetic origin", origin)
    p = as_finite_array("biasfield.plane_to_geodetic en", en)
    if p.ndim == 0 or p.shape[-1] != 2:
        raise ProblemError(
            f"biasfield.plane_to_geodetic en: expected (..., 2) East-North (m), got shape {p.shape}"
        )
    e, n = p[..., 0], p[..., 1]
    d2 = e**2 + n**2
    if np.any(d2 > (0.9 * _A) ** 2):
        raise ProblemError(
            "biasfield.plane_to_geodetic en: points beyond 0.9 R of the "
            "origin have no footprint on this plane"
        )
    rr = _A + o[2]
    u = np.sqrt(rr**2 - d2) - rr  # sphere through the origin point as a first guess
    for _ in range(_ITER):
        lat, lon, h = pymap3d.enu2geodetic(e, n, u, o[0], o[1], o[2])
        h = np.asarray(h, float)
        if np.all(np.abs(h) < 1e-7):
            break
        # dh/dU = cos(angle between the two verticals) = sqrt(1 − d²/R²) on the sphere
        u = u - h / np.sqrt(1.0 - d2 / rr**2)
    return np.asarray(lat, float), np.asarray(lon, float)


def locate(
    site: ArrayLike,
    slant_range: ArrayLike,
    azimuth: ArrayLike,
    height: ArrayLike,
    origin: ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """p_i⁻¹: the target seen by the radar at ``site`` at slant range (m) and azimuth (rad,
    clockwise from the radar's own north) whose height above the ellipsoid is ``height``
    (m). Returns latitude, longitude (deg) and its plane position East, North (m) in the
    frame of ``origin``. The elevation is solved by Newton iterations on the exact
    ``aer2geodetic`` (to < 1e-6 m in height); where no elevation gives that height (slant
    range shorter than the height difference, or beyond the horizon) the outputs are NaN."""
    s = site_geodetic("biasfield.locate site", site)
    o = site_geodetic("biasfield.locate origin", origin)
    r, az, h = np.broadcast_arrays(
        _arr("biasfield.locate slant_range", slant_range),
        _arr("biasfield.locate azimuth", azimuth),
        _arr("biasfield.locate height", height),
    )
    if np.any(r < 0):
        raise ProblemError("biasfield.locate slant_range: negative slant range")
    rs, rt = _A + s[2], _A + h
    with np.errstate(invalid="ignore", divide="ignore"):
        sin_el = (rt**2 - rs**2 - r**2) / (2.0 * r * rs)  # law of cosines on the sphere
    ok = (np.abs(sin_el) <= 1.0) & (r > 0)
    el = np.arcsin(np.clip(np.where(ok, sin_el, 0.0), -1.0, 1.0))
    azd = np.rad2deg(az)
    lat = lon = np.zeros(r.shape)
    for _ in range(_ITER):
        lat, lon, hh = pymap3d.aer2geodetic(azd, np.rad2deg(el), r, s[0], s[1], s[2])
        err = np.asarray(hh, float) - h
        if np.all(np.abs(err[ok]) < 1e-6):
            break
        # dh/d(el) on the sphere: r·rs·cos(el)/rt
        with np.errstate(invalid="ignore", divide="ignore"):
            step = err * rt / (r * rs * np.maximum(np.cos(el), 1e-6))
        el = np.clip(el - np.where(ok, step, 0.0), -np.pi / 2, np.pi / 2)
    lat = np.where(ok, np.asarray(lat, float), np.nan)
    lon = np.where(ok, np.asarray(lon, float), np.nan)
    en = np.full((*r.shape, 2), np.nan)
    if ok.any():
        en[ok] = common_plane(lat[ok], lon[ok], o)
    return lat, lon, en[..., 0], en[..., 1]


def to_polar3d(x: ArrayLike, h: ArrayLike, site: ArrayLike, origin: ArrayLike) -> FloatArray:
    """p_i(x; h): plane positions (..., 2) (m) at heights h (...,) (m) → (..., 2) [slant
    range (m), azimuth (rad)] of the radar at ``site``."""
    lat, lon = plane_to_geodetic(x, origin)
    r, az = measure(site, lat, lon, np.broadcast_to(_arr("h", h), lat.shape))
    return np.stack([r, az], axis=-1)


def from_polar3d(polar: ArrayLike, h: ArrayLike, site: ArrayLike, origin: ArrayLike) -> FloatArray:
    """p_i⁻¹(·; h): (..., 2) [slant range, azimuth] at heights h → plane positions (..., 2);
    ProblemError where no elevation reaches that height."""
    p = as_finite_array("polar", polar)
    if p.ndim == 0 or p.shape[-1] != 2:
        raise ProblemError(f"polar: expected (..., 2) [range, azimuth], got {p.shape}")
    _, _, e, n = locate(site, p[..., 0], p[..., 1], h, origin)
    if np.any(np.isnan(e)):
        raise ProblemError(
            f"polar: {int(np.isnan(e).sum())} (range, azimuth, height) have no "
            "position (slant range shorter than the height difference)"
        )
    return np.stack([e, n], axis=-1)


def polar_jacobian3d(x: ArrayLike, h: ArrayLike, site: ArrayLike, origin: ArrayLike) -> FloatArray:
    """∇p_i(x; h) = ∂(slant range, azimuth)/∂(East, North) at fixed height, (..., 2, 2).
    Rows as in :func:`~optmodels.biasfield.geometry.polar_jacobian`.

    By the chain rule through the footprint's latitude and longitude, both factors by
    central differences (±1e-5°, ≈ 1 m) of exact pymap3d maps with no iteration:
    ∂(r, α)/∂(φ, λ) (``geodetic2aer`` at height h) times the inverse of ∂(E, N)/∂(φ, λ)
    (``geodetic2enu`` of the footprint); relative error ~1e-9."""
    xx = as_finite_array("x", x)
    if xx.ndim == 0 or xx.shape[-1] != 2:
        raise ProblemError(f"x: expected points (..., 2), got shape {xx.shape}")
    hh = np.broadcast_to(_arr("h", h), xx.shape[:-1])
    s = site_geodetic("site", site)
    o = site_geodetic("origin", origin)
    lat, lon = plane_to_geodetic(xx, o)
    zero = np.zeros(lat.shape)
    d = _STEP_DEG
    pol_cols, en_cols = [], []
    for dlat, dlon in ((d, 0.0), (0.0, d)):
        az_hi, _, r_hi = pymap3d.geodetic2aer(lat + dlat, lon + dlon, hh, s[0], s[1], s[2])
        az_lo, _, r_lo = pymap3d.geodetic2aer(lat - dlat, lon - dlon, hh, s[0], s[1], s[2])
        pol_cols.append(
            np.stack(
                [np.asarray(r_hi) - r_lo, wrap_angle(np.deg2rad(np.asarray(az_hi) - az_lo))],
                axis=-1,
            )
            / (2 * d)
        )
        e_hi, n_hi, _ = pymap3d.geodetic2enu(lat + dlat, lon + dlon, zero, o[0], o[1], o[2])
        e_lo, n_lo, _ = pymap3d.geodetic2enu(lat - dlat, lon - dlon, zero, o[0], o[1], o[2])
        en_cols.append(
            np.stack([np.asarray(e_hi) - e_lo, np.asarray(n_hi) - n_lo], axis=-1) / (2 * d)
        )
    d_pol = np.stack(pol_cols, axis=-1)  # ∂(r, α)/∂(φ, λ)
    d_en = np.stack(en_cols, axis=-1)  # ∂(E, N)/∂(φ, λ), never singular below 0.9 R
    jac = d_pol @ np.linalg.inv(d_en)
    det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
    if np.any(~np.isfinite(det)) or np.any(det == 0):
        raise ProblemError(
            "x: the polar map is singular at a point (at or above the radar "
            "site, azimuth undefined)"
        )
    return jac


def plane_jacobian(x: ArrayLike, h: ArrayLike, site: ArrayLike, origin: ArrayLike) -> FloatArray:
    """∂(East, North)/∂(slant range, azimuth) at fixed height, (..., 2, 2): the inverse of
    :func:`polar_jacobian3d` (how a polar bias moves the plotted position on the plane)."""
    return np.asarray(np.linalg.inv(polar_jacobian3d(x, h, site, origin)), dtype=float)


def shift_from_bias3d(
    x: ArrayLike, h: ArrayLike, site: ArrayLike, origin: ArrayLike, f: ArrayLike
) -> FloatArray:
    """s_i(x) = p_i⁻¹(p_i(x; h) + f; h) − x, exact, for a polar bias f (..., 2)."""
    xx = as_finite_array("x", x)
    pol = to_polar3d(xx, h, site, origin) + as_finite_array("f", f)
    pol[..., 1] = wrap_angle(pol[..., 1])
    return from_polar3d(pol, h, site, origin) - xx


def bias_from_shift3d(
    x: ArrayLike, h: ArrayLike, site: ArrayLike, origin: ArrayLike, s: ArrayLike
) -> FloatArray:
    """f_i(x) = p_i(x + s; h) − p_i(x; h), exact, azimuth wrapped."""
    xx = as_finite_array("x", x)
    d = to_polar3d(xx + as_finite_array("s", s), h, site, origin) - to_polar3d(xx, h, site, origin)
    return np.stack([d[..., 0], wrap_angle(d[..., 1])], axis=-1)
