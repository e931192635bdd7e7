"""Per-object centred moments of the trajectories' data (paper 002, see the package notes
"Numerics").

Object j's own line (position ``p_j`` at its weighted mean time T_j, velocity ``V̂_j``) and
the sums N_j = Σw, M2_j = Σw(t − T_j)², Σw(t − T_j)(y − ȳ_j) are sufficient for the
least squares (1): every fit (8)-(9), (12)-(13), (3), the objective and the re-check are
computed from them without the cancellation of the paper's raw sums. Also here: the
time-resolution rule (:data:`TIME_RESOLUTION_MAX`, data refused as numerically singular),
which is applied when the moments are formed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optmodels.core import FloatArray, ProblemError
from optmodels.trajectories.data import TrajectoryData

#: float64 relative precision.
EPS = float(np.finfo(float).eps)

#: Time resolution ``eps·max|t_j| / std(t_j)`` of an object's float64 times (the relative
#: precision to which their spread, hence the velocity, is carried): above
#: TIME_RESOLUTION_WARN the status is at best OPTIMAL_INACCURATE, above
#: TIME_RESOLUTION_MAX the data are refused as numerically singular.
TIME_RESOLUTION_WARN = 1e-6
TIME_RESOLUTION_MAX = 1e-3


# --------------------------------------------------------------------------- centred moments
@dataclass(frozen=True)
class _Stats:
    """Per-object centred moments, (Q, d) per coordinate (the weights may differ).

    ``T_j`` is object j's weighted mean time (not stored: ``tbar + tcorr``, a float and a
    small correction), ``u = T_j − epoch`` the lever from the epoch, ``p`` and ``vhat``
    object j's own least-squares line (position at T_j, velocity), ``m2 = Σw(t − T_j)²``,
    ``tau`` (n, d) the centred times t − T_j and ``ry`` (n, d) the values minus ``p``.
    """

    s0: FloatArray
    tbar: FloatArray
    tcorr: FloatArray
    u: FloatArray
    m2: FloatArray
    p: FloatArray
    vhat: FloatArray
    tau: FloatArray
    ry: FloatArray
    span: FloatArray
    kappa: FloatArray


def _per(data: TrajectoryData, x: FloatArray) -> FloatArray:
    """Σ over each object's measurements (rows are stored object by object): (Q, ...)."""
    return np.add.reduceat(x, data.offsets, axis=0)


def _stats(data: TrajectoryData) -> _Stats:
    """The centred moments of ``data`` (cached on it).

    Raises
    ------
    ProblemError
        An object's times are not resolved by float64 at their magnitude (the design is
        numerically singular), or the moments overflow/underflow float64.
    """
    cached = data._cache.get("stats")
    if cached is not None:
        return cached
    obj, w, y = data.obj, data.w, data.y
    t = data.raw_t
    with np.errstate(all="ignore"):
        s0 = _per(data, w)
        t0 = t[data.offsets]
        tbar = t0[:, None] + _per(data, w * (t - t0[obj])[:, None]) / s0
        taup = t[:, None] - tbar[obj]
        tcorr = _per(data, w * taup) / s0
        tau = taup - tcorr[obj]
        y0 = y[data.offsets]
        ybar = y0 + _per(data, w * (y - y0[obj])) / s0
        ryp = y - ybar[obj]
        ycorr = _per(data, w * ryp) / s0
        p = ybar + ycorr
        ry = ryp - ycorr[obj]
        m2 = _per(data, w * tau * tau)
        sxy = _per(data, w * tau * ry)
        vhat = sxy / m2
        u = (tbar - data.epoch) + tcorr
        tmax = np.maximum.reduceat(np.abs(t), data.offsets)
        span = np.maximum.reduceat(t, data.offsets) - np.minimum.reduceat(t, data.offsets)
        kappa = EPS * tmax[:, None] / np.sqrt(m2 / s0)
    arrays = (s0, tbar, tcorr, u, m2, p, vhat, tau, ry, kappa)
    if not all(np.all(np.isfinite(a)) for a in arrays) or np.any(
        m2 < np.finfo(float).tiny * 1e16 * s0
    ):
        raise ProblemError(
            "times/values: the least-squares moments over- or underflow float64 (times "
            f"spread down to {np.min(span):.3g} s, weights {np.min(w):.3g}..{np.max(w):.3g}, "
            f"|values| up to {np.max(np.abs(y)):.3g}); change units"
        )
    worst = int(np.argmax(np.max(kappa, axis=1)))
    if float(np.max(kappa)) > TIME_RESOLUTION_MAX:
        raise ProblemError(
            f"times[{worst}]: AᵀA is numerically singular at the precision of the times: "
            f"object {worst}'s times spread over {span[worst]:.3g} s at |t| up to "
            f"{float(tmax[worst]):.3g} s, which float64 resolves only to "
            f"{float(np.max(kappa[worst])):.2g} relative; measure time from an origin nearer "
            "the data"
        )
    st = _Stats(s0, tbar, tcorr, u, m2, p, vhat, tau, ry, span, kappa)
    data._cache["stats"] = st
    return st
