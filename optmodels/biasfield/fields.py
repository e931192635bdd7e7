"""Bias fields f_i(x) = [range bias (m), azimuth bias (rad)] as functions of the true
position x (paper 001, (1) and section 1): constant, linear, smooth 2-D, or any callable."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import FloatArray, ProblemError, as_finite_array

__all__ = ["BiasField"]

FieldFunction = Callable[[FloatArray], FloatArray]


@dataclass(frozen=True)
class BiasField:
    """A polar bias field: ``field(x)`` maps positions (..., 2) to (..., 2) =
    [range bias (m), azimuth bias (rad)]. Build it with :meth:`constant`, :meth:`linear`,
    :meth:`smooth` or :meth:`from_callable`."""

    function: FieldFunction
    description: str = ""

    def __call__(self, x: ArrayLike) -> FloatArray:
        xx = as_finite_array("x", x)
        out = np.asarray(self.function(xx), dtype=float)
        if out.shape != xx.shape:
            raise ProblemError(f"field: returned shape {out.shape} for positions of shape "
                               f"{xx.shape}; expected the same shape ([range, azimuth])")
        if not np.all(np.isfinite(out)):
            raise ProblemError(f"field: non-finite bias ({self.description})")
        return out

    @classmethod
    def constant(cls, range_bias: float = 0.0, azimuth_bias: float = 0.0) -> BiasField:
        """The same bias everywhere (the parametric model (2) has range_bias = 0)."""
        b = np.array([float(range_bias), float(azimuth_bias)])
        return cls(lambda x: np.broadcast_to(b, x.shape).copy(),
                   f"constant ({b[0]:g} m, {b[1]:g} rad)")

    @classmethod
    def linear(cls, at_origin: ArrayLike, gradient: ArrayLike,
               origin: ArrayLike = (0.0, 0.0)) -> BiasField:
        """f(x) = at_origin + gradient (x − origin); ``gradient`` (2, 2): rows are the
        gradients of the range and the azimuth bias (per metre)."""
        f0 = as_finite_array("at_origin", at_origin, shape=(2,))
        g = as_finite_array("gradient", gradient, shape=(2, 2))
        o = as_finite_array("origin", origin, shape=(2,))
        return cls(lambda x: f0 + (x - o) @ g.T, "linear")

    @classmethod
    def smooth(cls, rng: np.random.Generator, *, center: ArrayLike, scale: float,
               range_amplitude: float, azimuth_amplitude: float, bumps: int = 4) -> BiasField:
        """A smooth random field: a constant plus ``bumps`` Gaussian bumps of width ~scale
        placed within ±scale of ``center``; each component's peak magnitude is about its
        amplitude."""
        c = as_finite_array("center", center, shape=(2,))
        if not scale > 0:
            raise ProblemError(f"scale: need a positive length, got {scale}")
        base = rng.uniform(-0.5, 0.5, 2)
        centers = c + rng.uniform(-scale, scale, (bumps, 2))
        widths = rng.uniform(0.5, 1.0, bumps) * scale
        weights = rng.uniform(-1.0, 1.0, (bumps, 2))
        amp = np.array([float(range_amplitude), float(azimuth_amplitude)])

        def f(x: FloatArray) -> FloatArray:
            d2 = np.sum((x[..., None, :] - centers) ** 2, axis=-1) / widths**2
            bump = np.exp(-0.5 * d2) @ weights
            return (base + bump) * amp

        return cls(f, f"smooth ({bumps} bumps, scale {scale:g} m)")

    @classmethod
    def from_callable(cls, function: FieldFunction, description: str = "user") -> BiasField:
        """Any vectorised function (..., 2) → (..., 2)."""
        if not callable(function):
            raise ProblemError("function: expected a callable (..., 2) -> (..., 2)")
        return cls(function, description)
