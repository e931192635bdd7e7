r"""Using an estimated bias field (paper 001, after section 4): evaluate it anywhere in the
covered area, correct plots with it, measure what registration buys, and score it against
a known field.

* :class:`FieldMap` / :func:`field_map`: the field of a solution on its cells, extended to
  the covered area by the piecewise-linear interpolant on the Delaunay triangulation of the
  cell centres (consistent with the smoothness functional (9): with weights
  1/‖x̌_i − x̌_j‖², J is a sum of squared difference quotients along the edges, a discrete
  Dirichlet energy, and the P1 interpolant is the finite-element function of that energy
  with the cell values at the nodes; unlike the graph's own harmonic extension — the
  1/d²-weighted mean of the neighbours, flat at every centre — it is exact for linear
  fields). It reproduces the cell values at the centres exactly (bit for bit), a linear
  field everywhere, and a smooth field to ½·h²·max‖∇²f‖ (h the longest edge of the
  triangle holding the point; docs/formulations.md). Outside the convex hull of the
  centres, or farther than ``max_distance`` from every centre, the field is not defined:
  NaN, and :meth:`FieldMap.covered` says where. A map carries the frame it was estimated
  in (radar names, sites; geodetic sites and origin for the exact 3-D chain), saved with
  it, and refuses a radar set that differs (:meth:`FieldMap.check_radars`).
  :meth:`~optmodels.biasfield.solution.FieldSolution.at` is this map of a solution.
* :func:`correct_plots`: f_i subtracted from radar i's (range, azimuth) at each plot's
  position (fixed point: the bias is a function of the *true* position x, evaluated at the
  corrected position; two passes change it by O(‖∇f‖·‖s‖), below 1e-6 of the bias for
  fields smooth over ≥ 10 km).
* :func:`registration_error`: the disagreement between radars that see the same aircraft at
  the same time: radar i's plot positions against radar j's track interpolated at those
  times (a local quadratic in time through radar j's plots, which follows turns), averaged
  per area (a square grid) so that the measurement noise averages out, per radar pair and
  overall.
* :func:`score`: the RMS error of a field against a known one at the cell centres, split
  into the per-cell common shift (unobservable without a reference: paper 001, section 3)
  and the rest.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield.correction import REASONS, correct_plots, seen_by_others
from optmodels.biasfield.correction import Corrected as Corrected
from optmodels.biasfield.data import FieldData, uncertainty_sets
from optmodels.biasfield.fieldmap import FieldMap, field_map
from optmodels.biasfield.geometry import wrap_angle
from optmodels.biasfield.registration import RegistrationError, registration_error
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_finite_array,
    as_instance,
)

__all__ = [
    "REASONS",
    "FieldMap",
    "FieldScore",
    "RegistrationError",
    "correct_plots",
    "field_map",
    "registration_error",
    "score",
    "seen_by_others",
]


# ----------------------------------------------------------------------------- score
@dataclass(frozen=True)
class FieldScore:
    """RMS error of a field against the truth at the cell centres, per component.

    ``total``, ``shift`` and ``rest``: (2,) RMS over cells and radars of [range (m),
    azimuth (rad)]; ``shift`` is the part of the error that a per-cell common Cartesian
    shift of all radars explains (the unobservable η_k of (10), fitted in the P metric),
    ``rest`` what remains (what the data do determine). ``*_m``: the same as horizontal
    distances on the common plane (m), each radar's polar error mapped through its
    Jacobian.
    """

    total: FloatArray
    shift: FloatArray
    rest: FloatArray
    total_m: float
    shift_m: float
    rest_m: float

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name in ("total", "shift", "rest"):
            v = getattr(self, name)
            out[name] = {
                "range_m": float(v[0]),
                "azimuth_deg": float(np.rad2deg(v[1])),
                "horizontal_m": float(getattr(self, f"{name}_m")),
            }
        return out


def score(field: ArrayLike, truth: ArrayLike, data: FieldData) -> FieldScore:
    """Error of ``field`` (K, m, 2) — e.g. ``solution.field`` — against ``truth`` (K, m, 2),
    the true [range, azimuth] biases at the cell centres, split into the per-cell common
    shift and the rest.

    In cell k the error e_k (2m,) is projected on the columns of Φ¹_k (10) (the polar
    image of a common shift δη of every radar) in the metric P of (9):
    δη_k = (Φ¹_kᵀ P Φ¹_k)⁻¹ Φ¹_kᵀ P e_k; shift = Φ¹_k δη_k, rest = e_k − shift.
    """
    fn = "biasfield.score"
    data = as_instance(f"{fn} data", data, FieldData)
    k, m = data.k, data.m
    f = as_finite_array(f"{fn} field", field, shape=(k, m, 2), max_abs=MAX_MAGNITUDE)
    t = as_finite_array(f"{fn} truth", truth, shape=(k, m, 2), max_abs=MAX_MAGNITUDE)
    e = f - t
    e[..., 1] = wrap_angle(e[..., 1])
    seen = data.subsets
    e[~seen] = 0.0  # a radar's error counts only on the cells it sees
    _, phi1 = uncertainty_sets(data)
    coo = phi1.tocoo()  # block-diagonal, (2m, 2) blocks; never densified (K may be 1e4)
    jac = np.zeros((k, 2 * m, 2))
    kk = coo.col // 2
    jac[kk, coo.row - 2 * m * kk, coo.col % 2] = coo.data
    p = data.P if data.P.shape == (2 * m, 2 * m) else np.kron(np.eye(m), data.P)
    ev = e.reshape(k, 2 * m)
    a = np.einsum("kia,ij,kjb->kab", jac, p, jac)
    rhs = np.einsum("kia,ij,kj->ka", jac, p, ev)
    try:
        deta = np.linalg.solve(a, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        raise ProblemError(
            f"{fn} data: a cell's common shift is not determined (Φ¹_kᵀPΦ¹_k singular)"
        ) from None
    sh = np.einsum("kia,ka->ki", jac, deta).reshape(k, m, 2)
    rest = e - sh
    rest[~seen] = 0.0
    jb = jac.reshape(k, m, 2, 2).copy()  # ∂(r, α)/∂(x, y) of radar i at cell k
    jb[~seen] = np.eye(2)  # (zero rows of the radars outside S_k; their errors are 0)

    def metres(err: FloatArray) -> float:
        d = np.linalg.solve(jb, err[..., None])[..., 0]
        return float(np.sqrt(np.sum(d * d) / seen.sum()))

    def rms(err: FloatArray) -> FloatArray:
        return np.sqrt(np.sum(err.reshape(-1, 2) ** 2, axis=0) / seen.sum())

    return FieldScore(rms(e), rms(sh), rms(rest), metres(e), metres(sh), metres(rest))
