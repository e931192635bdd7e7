r"""Radar polar coordinates ↔ Cartesian, with one azimuth convention (base layer).

Convention (every problem that converts radar measurements uses it): a radar at ``site``
measures the **range** ``r`` (m, slant), the **azimuth** ``β`` (rad, **clockwise from
north**, i.e. from the frame's +y axis towards +x, in (−π, π]) and, in 3-D, the
**elevation** ``ε`` (rad, up from the horizontal plane). The Cartesian frame is the radar's
local flat East-North-Up: x east, y north, z up (metres), so that

.. math::
    x = r\cos\varepsilon\sin\beta,\quad y = r\cos\varepsilon\cos\beta,\quad
    z = r\sin\varepsilon

(2-D: ``ε = 0``, ``x = r sin β``, ``y = r cos β``). This is the navigation convention of the
papers 000 (plane of maneuver) and 001 (bias field); a **mathematical** angle θ
(counter-clockwise from +x, as paper 004's sensor cells use) is ``θ = π/2 − β``
(:func:`math_angle`, :func:`azimuth_from_math_angle`).

No earth curvature and no refraction: for geodetic points convert them to the radar's ENU
first (``pymap3d.geodetic2enu``; :mod:`optmodels.biasfield.geometry3d` for the exact 3-D
geometry). These are raw-array kernels (no argument checks: the public entry points that
call them check their arguments and name them).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "azimuth_from_math_angle",
    "from_polar2d",
    "from_polar3d",
    "math_angle",
    "to_polar2d",
    "to_polar3d",
]

Float = NDArray[np.float64]


def to_polar3d(offsets: Float) -> Float:
    """``(N, 3)`` range (m), azimuth (rad, clockwise from north, in (−π, π]) and elevation
    (rad, up) of ENU ``offsets`` (N, 3) (point minus site, m; not at the site)."""
    d = np.asarray(offsets, dtype=float)
    r = np.linalg.norm(d, axis=1)
    return np.column_stack(
        [r, np.arctan2(d[:, 0], d[:, 1]), np.arcsin(np.clip(d[:, 2] / r, -1.0, 1.0))]
    )


def from_polar3d(polar: Float) -> Float:
    """ENU offsets (N, 3) from the site (m) of ``(N, 3)`` range (m), azimuth (rad,
    clockwise from north), elevation (rad): ``E = r cos ε sin β``, ``N = r cos ε cos β``,
    ``U = r sin ε``."""
    p = np.asarray(polar, dtype=float)
    r, az, el = p[:, 0], p[:, 1], p[:, 2]
    return np.column_stack(
        [r * np.cos(el) * np.sin(az), r * np.cos(el) * np.cos(az), r * np.sin(el)]
    )


def to_polar2d(offsets: Float) -> Float:
    """``(N, 2)`` range (m) and azimuth (rad, clockwise from north, in (−π, π]) of
    east-north ``offsets`` (N, 2) (m)."""
    d = np.asarray(offsets, dtype=float)
    return np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 0], d[:, 1])])


def from_polar2d(polar: Float) -> Float:
    """East-north offsets (N, 2) (m) of ``(N, 2)`` range (m) and azimuth (rad, clockwise
    from north): ``E = r sin β``, ``N = r cos β``."""
    p = np.asarray(polar, dtype=float)
    return np.column_stack([p[:, 0] * np.sin(p[:, 1]), p[:, 0] * np.cos(p[:, 1])])


def math_angle(azimuth: Float) -> Float:
    """The mathematical angle θ = π/2 − β (rad, counter-clockwise from +x) of azimuths β
    (rad, clockwise from north), wrapped to (−π, π]."""
    theta = np.pi / 2 - np.asarray(azimuth, dtype=float)
    return np.pi - np.mod(np.pi - theta, 2 * np.pi)


def azimuth_from_math_angle(theta: Float) -> Float:
    """The azimuth β = π/2 − θ (rad, clockwise from north, in (−π, π]) of mathematical
    angles θ (rad, counter-clockwise from +x)."""
    return math_angle(theta)
