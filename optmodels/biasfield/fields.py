"""Bias fields f_i(x) = [range bias (m), azimuth bias (rad)] as functions of the true
position x (paper 001, (1) and section 1): constant, linear, smooth 2-D, or any callable."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_number,
    as_positive,
)

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
        xx = as_finite_array("biasfield.BiasField x", x, max_abs=MAX_MAGNITUDE)
        if xx.ndim == 0 or xx.shape[-1] != 2:
            raise ProblemError(
                f"biasfield.BiasField x: expected positions (..., 2) in m, got shape {xx.shape}"
            )
        try:
            out = np.asarray(self.function(xx), dtype=float)
        except (TypeError, ValueError) as exc:
            raise ProblemError(
                f"biasfield.BiasField function: failed on positions of shape {xx.shape} ({exc})"
            ) from None
        if out.shape != xx.shape:
            raise ProblemError(
                f"biasfield.BiasField function: returned shape {out.shape} for "
                f"positions of shape {xx.shape}; expected the same shape "
                "([range, azimuth])"
            )
        if not np.all(np.isfinite(out)):
            raise ProblemError(
                f"biasfield.BiasField function: non-finite bias ({self.description})"
            )
        return out

    @classmethod
    def constant(cls, range_bias: float = 0.0, azimuth_bias: float = 0.0) -> BiasField:
        """The same bias everywhere: ``range_bias`` (m), ``azimuth_bias`` (rad); the
        parametric model (2) has range_bias = 0."""
        b = np.array(
            [
                as_number("biasfield.BiasField.constant range_bias (m)", range_bias),
                as_number("biasfield.BiasField.constant azimuth_bias (rad)", azimuth_bias),
            ]
        )
        return cls(
            lambda x: np.broadcast_to(b, x.shape).copy(), f"constant ({b[0]:g} m, {b[1]:g} rad)"
        )

    @classmethod
    def linear(
        cls, at_origin: ArrayLike, gradient: ArrayLike, origin: ArrayLike = (0.0, 0.0)
    ) -> BiasField:
        """f(x) = at_origin + gradient (x − origin); ``gradient`` (2, 2): rows are the
        gradients of the range and the azimuth bias (per metre)."""
        fn = "biasfield.BiasField.linear"
        f0 = as_finite_array(f"{fn} at_origin", at_origin, shape=(2,), max_abs=MAX_MAGNITUDE)
        g = as_finite_array(f"{fn} gradient", gradient, shape=(2, 2), max_abs=MAX_MAGNITUDE)
        o = as_finite_array(f"{fn} origin", origin, shape=(2,), max_abs=MAX_MAGNITUDE)
        return cls(lambda x: f0 + (x - o) @ g.T, "linear")

    @classmethod
    def smooth(
        cls,
        rng: np.random.Generator,
        *,
        center: ArrayLike,
        scale: float,
        range_amplitude: float,
        azimuth_amplitude: float,
        bumps: int = 4,
    ) -> BiasField:
        """A smooth random field: a constant plus ``bumps`` Gaussian bumps of width ~scale
        placed within ±scale of ``center``; each component's peak magnitude is about its
        amplitude (``range_amplitude`` m, ``azimuth_amplitude`` rad; ``scale`` m)."""
        fn = "biasfield.BiasField.smooth"
        if not isinstance(rng, np.random.Generator):
            raise ProblemError(
                f"{fn} rng: expected a numpy.random.Generator "
                "(numpy.random.default_rng(seed)), got "
                f"{type(rng).__name__}"
            )
        c = as_finite_array(f"{fn} center", center, shape=(2,), max_abs=MAX_MAGNITUDE)
        scale = as_positive(f"{fn} scale (m)", scale)
        range_amplitude = as_number(f"{fn} range_amplitude (m)", range_amplitude)
        azimuth_amplitude = as_number(f"{fn} azimuth_amplitude (rad)", azimuth_amplitude)
        bumps = as_count(f"{fn} bumps", bumps, maximum=10_000)
        base = rng.uniform(-0.5, 0.5, 2)
        centers = c + rng.uniform(-scale, scale, (bumps, 2))
        widths = rng.uniform(0.5, 1.0, bumps) * scale
        weights = rng.uniform(-1.0, 1.0, (bumps, 2))
        amp = np.array([range_amplitude, azimuth_amplitude])

        def f(x: FloatArray) -> FloatArray:
            d2 = np.sum((x[..., None, :] - centers) ** 2, axis=-1) / widths**2
            bump = np.exp(-0.5 * d2) @ weights
            return (base + bump) * amp

        return cls(f, f"smooth ({bumps} bumps, scale {scale:g} m)")

    @classmethod
    def from_callable(cls, function: FieldFunction, description: str = "user") -> BiasField:
        """Any vectorised function (..., 2) → (..., 2)."""
        if not callable(function):
            raise ProblemError(
                "biasfield.BiasField.from_callable function: expected a "
                "callable (..., 2) -> (..., 2)"
            )
        if not isinstance(description, str):
            raise ProblemError(
                "biasfield.BiasField.from_callable description: expected a "
                f"str, got {type(description).__name__}"
            )
        return cls(function, description)
