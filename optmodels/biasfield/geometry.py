r"""Radar geometry of paper 001, section 1: the polar map p_i, its inverse and Jacobian,
and the two descriptions of a bias, the Cartesian shift s_i and the polar bias f_i.

p_i: x ↦ [r(x), α(x)]ᵀ with r = ‖x − site‖ and α the azimuth **clockwise from North**,
α = atan2(dx, dy), wrapped to (−π, π] (DESIGN.md). A bias is, at a true position x,

.. math::
    f_i(x) = p_i(x + s_i(x)) - p_i(x), \qquad s_i(x) = p_i^{-1}(p_i(x) + f_i(x)) - x,

the azimuth difference wrapped to (−π, π]. Every function broadcasts over leading axes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import FloatArray, ProblemError, as_finite_array, as_float_array

__all__ = [
    "bias_from_shift",
    "from_polar",
    "polar_jacobian",
    "shift_from_bias",
    "to_polar",
    "wrap_angle",
]


def wrap_angle(a: ArrayLike) -> FloatArray:
    """Wrap angles (rad) to (−π, π]. NaN stays NaN; text, ragged rows, ``None`` entries,
    complex values and mappings are one :class:`ProblemError` naming ``a``."""
    # fast path for the package's own float64 arrays (millions of plot azimuths)
    if type(a) is np.ndarray and a.dtype == np.float64:
        arr: FloatArray = a
    else:
        arr = as_float_array("biasfield.wrap_angle a", a)
    out = np.mod(arr + np.pi, 2 * np.pi) - np.pi
    return np.where(out == -np.pi, np.pi, out)


def _points(name: str, x: ArrayLike) -> FloatArray:
    arr = as_finite_array(name, x)
    if arr.ndim == 0 or arr.shape[-1] != 2:
        raise ProblemError(f"{name}: expected points (..., 2), got shape {arr.shape}")
    return arr


def _site(site: ArrayLike) -> FloatArray:
    return as_finite_array("site", site, shape=(2,))


def to_polar(x: ArrayLike, site: ArrayLike) -> FloatArray:
    """p_i(x): (..., 2) Cartesian East-North (m) → (..., 2) [range (m), azimuth (rad)]."""
    d = _points("x", x) - _site(site)
    return np.stack([np.hypot(d[..., 0], d[..., 1]), np.arctan2(d[..., 0], d[..., 1])], axis=-1)


def from_polar(polar: ArrayLike, site: ArrayLike) -> FloatArray:
    """p_i⁻¹: (..., 2) [range, azimuth] → Cartesian. Negative ranges are refused."""
    p = _points("polar", polar)
    if np.any(p[..., 0] < 0):
        raise ProblemError("polar: negative range")
    r, az = p[..., 0], p[..., 1]
    return _site(site) + np.stack([r * np.sin(az), r * np.cos(az)], axis=-1)


def polar_jacobian(x: ArrayLike, site: ArrayLike) -> FloatArray:
    """∇p_i(x), (..., 2, 2): rows ∂r/∂(x, y) = (dx, dy)/r and ∂α/∂(x, y) = (dy, −dx)/r².

    Raises :class:`ProblemError` at the site itself (the azimuth is undefined there).
    """
    d = _points("x", x) - _site(site)
    r2 = d[..., 0] ** 2 + d[..., 1] ** 2
    if np.any(r2 == 0):
        raise ProblemError("x: a point coincides with the radar site (azimuth undefined)")
    r = np.sqrt(r2)
    return np.stack(
        [
            np.stack([d[..., 0] / r, d[..., 1] / r], axis=-1),
            np.stack([d[..., 1] / r2, -d[..., 0] / r2], axis=-1),
        ],
        axis=-2,
    )


def shift_from_bias(x: ArrayLike, site: ArrayLike, f: ArrayLike) -> FloatArray:
    """s_i(x) = p_i⁻¹(p_i(x) + f) − x for a polar bias f = [range, azimuth] (..., 2)."""
    xx = _points("x", x)
    ff = _points("f", f)
    return from_polar(to_polar(xx, site) + ff, site) - xx


def bias_from_shift(x: ArrayLike, site: ArrayLike, s: ArrayLike) -> FloatArray:
    """f_i(x) = p_i(x + s) − p_i(x) for a Cartesian shift s (..., 2); azimuth wrapped."""
    xx = _points("x", x)
    d = to_polar(xx + _points("s", s), site) - to_polar(xx, site)
    return np.stack([d[..., 0], wrap_angle(d[..., 1])], axis=-1)
