r"""Weighted moments of index ranges of a track, for sliding windows (paper 000, (1.5)).

The closed form (1.5)-(1.7) of a window needs only three weighted sums of its points,
:math:`s_0 = \sum w_i`, :math:`s_1 = \sum w_i x_i`, :math:`s_2 = \sum w_i x_i x_i^T`
(:math:`w_i = \alpha_i^{-2}`), reduced to the weight, the weighted mean and the centred
scatter ``Q`` (1.5). A sliding window adds one point and removes the oldest:
:math:`S(k+1) = S(k) + t_{k+1} - t_{lo}`, O(1) per step. Done naively about a fixed
origin, the removal cancels: the running sums grow with the length of the track and the
distance from the origin while ``Q`` of the window stays small, and the difference loses
:math:`\epsilon \cdot (\text{size of the sums}) / \|Q\|` relative accuracy.

:func:`range_moments` computes the same sums for every window at once without that
cancellation (the "two-stack queue" of sliding aggregates, van Herk / Gil-Werman): the
track is cut into epochs of ``L`` points (``L`` at least the longest window), each with
its own reference point (its first point) and the coordinates divided by the spread of
the track. Within an epoch it keeps prefix sums (running from the epoch's start) and
suffix sums (running backwards from its end). A window of at most ``L`` points lies in
one epoch or in two consecutive ones:

* across an epoch boundary: suffix of the first epoch + prefix of the second, combined
  as centred moments (Chan's parallel formula :math:`Q = Q_A + Q_B + \frac{w_Aw_B}{w_A +
  w_B} d d^T`, ``d`` the difference of the means) -- no subtraction at all;
* inside one epoch: a difference of two prefix sums of the same epoch -- at most ``L``
  terms about a point of the window's own epoch, so the cancellation is bounded; where
  the discarded prefix still dominates the window (the trace of its absolute second
  moments above :data:`_RECOMPUTE_RATIO` times the window's), the window is recomputed
  from scratch.

This is the running-sum update with removal in which every sum is recomputed from
scratch once per epoch. The round-off bound ``qabs`` handed to the re-check of
:func:`optmodels.plane.closedform._closed_form_from_sums` covers the terms that were
actually summed (the whole prefix where one was subtracted), so the re-check's
``numerical_error`` accounts for whatever cancellation remains.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optmodels.core import FloatArray, ProblemError, as_count, as_positive

#: A window inside one epoch is recomputed from scratch when the absolute second moments
#: of the prefix it subtracts exceed this multiple of its own (relative cancellation
#: then ≤ ~1e3 ulps of the window's sums).
_RECOMPUTE_RATIO = 1e3


@dataclass(frozen=True)
class Moments:
    """Weighted moments of K index ranges (scaled coordinates: metres / ``spread``).

    ``s0`` (K,) Σ w; ``mean`` (K, 3) weighted mean in the track's coordinates (m);
    ``q`` (K, 3, 3) centred scatter Q (1.5) divided by spread²; ``qabs`` (K, 3, 3) a bound
    of the magnitudes summed into ``q`` (for its round-off); ``count`` (K,) points;
    ``spread`` the scale (m); ``recomputed`` (K,) windows summed from scratch.
    """

    s0: FloatArray
    mean: FloatArray
    q: FloatArray
    qabs: FloatArray
    count: FloatArray
    spread: float
    recomputed: np.ndarray


def _outer(a: FloatArray, b: FloatArray) -> FloatArray:
    return a[..., :, None] * b[..., None, :]


def track_spread(points: FloatArray) -> float:
    """RMS distance of the points from their mean (m): the scale of the sums."""
    s = float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
    return s if s > 0 else 1.0


def direct_moments(
    points: FloatArray, w: FloatArray, lo: np.ndarray, hi: np.ndarray, spread: float
) -> Moments:
    """From-scratch moments of the ranges ``[lo_k, hi_k]`` (inclusive), one loop per
    range: the reference that :func:`range_moments` is tested against."""
    k = len(lo)
    s0 = np.empty(k)
    mean = np.empty((k, 3))
    q = np.empty((k, 3, 3))
    qabs = np.empty((k, 3, 3))
    for j in range(k):
        x = points[lo[j] : hi[j] + 1]
        ww = w[lo[j] : hi[j] + 1]
        ref = x[0]
        y = (x - ref) / spread
        s0[j] = np.sum(ww)
        m = ww @ y / s0[j]
        yc = y - m
        q[j] = (yc * ww[:, None]).T @ yc
        ay = np.abs(y)
        qabs[j] = (ay * ww[:, None]).T @ ay + s0[j] * np.outer(np.abs(m), np.abs(m))
        mean[j] = ref + spread * m
    return Moments(
        s0=s0,
        mean=mean,
        q=q,
        qabs=qabs,
        count=(hi - lo + 1).astype(float),
        spread=spread,
        recomputed=np.ones(k, dtype=bool),
    )


def range_moments(
    points: FloatArray,
    w: FloatArray,
    lo: np.ndarray,
    hi: np.ndarray,
    *,
    origin: int = 0,
    spread: float | None = None,
) -> Moments:
    """Moments of the index ranges ``[lo_k, hi_k]`` (inclusive, ``origin <= lo_k <= hi_k``)
    of ``points`` (N, 3) with weights ``w`` (N,), in O(1) per range after an O(N) pass.

    Epochs of ``L = max(hi - lo + 1)`` points start at ``origin`` (see the module
    docstring); every range then spans at most two epochs.
    """
    lo = np.asarray(lo, dtype=np.int64)
    hi = np.asarray(hi, dtype=np.int64)
    sp = track_spread(points) if spread is None else spread
    k = len(lo)
    if k == 0:
        z = np.zeros(0)
        return Moments(
            s0=z,
            mean=np.zeros((0, 3)),
            q=np.zeros((0, 3, 3)),
            qabs=np.zeros((0, 3, 3)),
            count=z,
            spread=sp,
            recomputed=np.zeros(0, dtype=bool),
        )
    length = int(np.max(hi - lo + 1))
    end = int(np.max(hi)) + 1
    idx = np.arange(origin, end)
    epoch = (idx - origin) // length
    first = origin + epoch * length  # epoch start of each point
    x = points[origin:end]
    y = (x - points[first]) / sp
    ww = w[origin:end]
    ay = np.abs(y)
    t0 = ww
    t1 = ww[:, None] * y
    t2 = ww[:, None, None] * _outer(y, y)
    t1a = ww[:, None] * ay
    t2a = ww[:, None, None] * _outer(ay, ay)
    n_ep = int(epoch[-1]) + 1
    pad = n_ep * length - len(idx)

    def _scan(a: FloatArray, reverse: bool) -> FloatArray:
        shaped = np.concatenate([a, np.zeros((pad, *a.shape[1:]))]).reshape(
            (n_ep, length, *a.shape[1:])
        )
        if reverse:
            out = np.cumsum(shaped[:, ::-1], axis=1)[:, ::-1]
        else:
            out = np.cumsum(shaped, axis=1)
        return out.reshape((n_ep * length, *a.shape[1:]))[: len(idx)]

    p0, p1, p2, p1a, p2a = (_scan(a, False) for a in (t0, t1, t2, t1a, t2a))
    e_lo = (lo - origin) // length
    e_hi = (hi - origin) // length
    span = e_hi > e_lo
    i_lo = lo - origin
    i_hi = hi - origin

    s0 = np.empty(k)
    mean = np.empty((k, 3))
    q = np.empty((k, 3, 3))
    qabs = np.empty((k, 3, 3))
    recomputed = np.zeros(k, dtype=bool)

    # --- inside one epoch: prefix difference
    one = ~span
    if np.any(one):
        a = i_lo[one]
        b = i_hi[one]
        at_start = (a % length) == 0
        prev = np.where(at_start, 0, a - 1)
        keep = (~at_start)[:, None]
        a0 = p0[b] - np.where(~at_start, p0[prev], 0.0)
        a1 = p1[b] - np.where(keep, p1[prev], 0.0)
        a2 = p2[b] - np.where(keep[:, :, None], p2[prev], 0.0)
        m = a1 / a0[:, None]
        s0[one] = a0
        q[one] = a2 - a0[:, None, None] * _outer(m, m)
        mean[one] = points[first[a]] + sp * m
        qabs[one] = p2a[b] + (_outer(p1a[b], np.abs(m)) + _outer(np.abs(m), p1a[b]))
        own = np.trace(p2a[b] - np.where(keep[:, :, None], p2a[prev], 0.0), axis1=1, axis2=2)
        total = np.trace(p2a[b], axis1=1, axis2=2)
        bad = total > _RECOMPUTE_RATIO * np.maximum(own, np.finfo(float).tiny)
        if np.any(bad):
            sel = np.flatnonzero(one)[bad]
            d = direct_moments(points, w, lo[sel], hi[sel], sp)
            s0[sel], mean[sel], q[sel], qabs[sel] = d.s0, d.mean, d.q, d.qabs
            recomputed[sel] = True

    # --- across one boundary: suffix of the first epoch + prefix of the second
    if np.any(span):
        a = i_lo[span]
        b = i_hi[span]
        # suffix sums of the first epoch from a (the reverse scan: the epoch's total
        # minus the prefix before a would cancel)
        sa0, sa1, sa2, sa1a, sa2a = (_scan(v, True)[a] for v in (t0, t1, t2, t1a, t2a))
        ma = sa1 / sa0[:, None]
        qa = sa2 - sa0[:, None, None] * _outer(ma, ma)
        b0, b1, b2 = p0[b], p1[b], p2[b]
        mb = b1 / b0[:, None]
        qb = b2 - b0[:, None, None] * _outer(mb, mb)
        ref_a = points[first[a]]
        ref_b = points[first[b]]
        d = (ref_a - ref_b) / sp + ma - mb
        tot = sa0 + b0
        f = sa0 * b0 / tot
        s0[span] = tot
        q[span] = qa + qb + f[:, None, None] * _outer(d, d)
        mean[span] = ref_b + sp * (mb + (sa0 / tot)[:, None] * d)
        qabs[span] = (
            sa2a
            + p2a[b]
            + _outer(sa1a, np.abs(ma))
            + _outer(p1a[b], np.abs(mb))
            + f[:, None, None] * _outer(np.abs(d), np.abs(d))
        )
    q = 0.5 * (q + np.swapaxes(q, -1, -2))
    return Moments(
        s0=s0,
        mean=mean,
        q=q,
        qabs=qabs,
        count=(hi - lo + 1).astype(float),
        spread=sp,
        recomputed=recomputed,
    )


# =========================================================================== the window's unit
_WINDOW_HELP = (
    'write window_seconds=40.0 (or window="40s") for the last 40 s, '
    'window_points=100 (or window="100pts") for the last 100 measurements, or '
    'nothing (window=None, "growing") for a growing window'
)


def window_spec(
    window: str | None = None,
    *,
    window_points: int | None = None,
    window_seconds: float | None = None,
    where: str = "plane.track",
) -> float | int | None:
    """The sliding window of :func:`optmodels.plane.tracking.track`, with its unit
    stated: ``window_seconds`` (s), ``window_points`` (measurements), or ``window`` as
    text with a unit (``"40s"``, ``"100pts"``, ``"growing"``); at most one. A bare
    number is refused: ``40`` (points?) and ``40.0`` (seconds?) read alike (issue 26).

    Returns the internal form: a float (seconds), an int (points) or ``None`` (growing).

    Raises
    ------
    ProblemError
        A bare number, two of the three given, or a value out of range; the message says
        what to write.
    """
    given = [
        k
        for k, v in (
            ("window", window),
            ("window_points", window_points),
            ("window_seconds", window_seconds),
        )
        if v is not None
    ]
    if len(given) > 1:
        raise ProblemError(f"{where} {'/'.join(given)}: give one window, got {len(given)}")
    if window_points is not None:
        if isinstance(window_points, bool | np.bool_) or not isinstance(
            window_points, int | np.integer
        ):
            raise ProblemError(
                f"{where} window_points: expected a whole number of "
                f"measurements (>= 4), got {window_points!r}"
            )
        return as_count(f"{where} window_points", window_points, minimum=4)
    if window_seconds is not None:
        if isinstance(window_seconds, bool | np.bool_):
            raise ProblemError(f"{where} window_seconds: expected seconds, got {window_seconds!r}")
        return as_positive(f"{where} window_seconds", window_seconds)
    if window is None:
        return None
    if not isinstance(window, str):
        raise ProblemError(
            f"{where} window: {window!r} does not say its unit (points or seconds?); {_WINDOW_HELP}"
        )
    return parse_window_text(window, where)


def parse_window_text(text: str, where: str) -> float | int | None:
    """``"40s"`` / ``"40 s"`` → 40.0 s; ``"100pts"`` / ``"100 points"`` → 100 points;
    ``"growing"`` → ``None``; anything else (a bare ``"40"``) refused."""
    raw = text.strip().lower().replace(" ", "")
    if raw in ("growing", "none", "all"):
        return None
    for suffix in ("seconds", "second", "sec", "s"):
        if raw.endswith(suffix):
            try:
                value = float(raw[: -len(suffix)])
            except ValueError:
                break
            return as_positive(f"{where} window (s)", value)
    for suffix in ("points", "point", "pts", "pt"):
        if raw.endswith(suffix):
            try:
                count = int(raw[: -len(suffix)])
            except ValueError:
                break
            return as_count(f"{where} window (points)", count, minimum=4)
    raise ProblemError(
        f"{where} window: {text!r} does not say its unit (points or seconds?); {_WINDOW_HELP}"
    )


def window_label(window: float | int | None) -> str:
    """The text form of a window (``"40s"``, ``"100pts"``, ``"growing"``): what
    :func:`window_spec` reads back."""
    if window is None:
        return "growing"
    if isinstance(window, int):
        return f"{window}pts"
    return f"{window:g}s"
