"""Covariances and variance ratios of paper 002: Ψ (14) of the data's design, the
introduction's single-line variances, Ψ* (16)-(20) of two objects as printed and
corrected, the conclusions' η and η0 for any ``Q`` and ``N``, and their general form for
the data's own times (:func:`variance_ratios`).

(Named ``covariances`` so that the module does not shadow the function
``optmodels.trajectories.covariance``.)
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from optmodels.core import (
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_flag,
    as_instance,
    as_positive,
)
from optmodels.trajectories.data import Family, FamilyName, TrajectoryData, resolve_family
from optmodels.trajectories.fits import _fit
from optmodels.trajectories.solution import _shape


def covariance(data: TrajectoryData, family: FamilyName | Family) -> FloatArray:
    """Ψ (14): σ²(AᵀA)⁻¹, or (AᵀWA)⁻¹ with per-measurement variances, with A the design
    matrix, computed from centred moments (Schur complements of the paper's families, QR of
    the reduced design for a custom one). (R, R) for scalar values, (d, R, R) for vector
    values.

    Raises
    ------
    ProblemError
        The design is numerically singular (see :class:`TrajectoryData`).
    """
    as_instance("trajectories.covariance data", data, TrajectoryData)
    fam = resolve_family(family, data.n_objects)
    cov = _fit(data, fam).cov
    return cov.copy() if data.vector else cov[0].copy()


# --------------------------------------------------------------------------- covariances
def independent_variances(n: int, dt: float = 1.0, sigma2: float = 1.0) -> tuple[float, float]:
    """Variances of a single line's (y0, V) from ``N`` equally spaced measurements
    ``t_i = (i − 1)·dt`` (the introduction): σ²·2(2N−1)/(N(N+1)) and σ²·12/(N(N²−1)dt²).

    The paper calls these "СКО" and omits σ²; they are variances (y0 at the first
    measurement)."""
    n = as_count("trajectories.independent_variances n", n, minimum=2)
    dt = as_positive("trajectories.independent_variances dt", dt)
    sigma2 = as_positive("trajectories.independent_variances sigma2", sigma2)
    return (sigma2 * 2 * (2 * n - 1) / (n * (n + 1)), sigma2 * 12 / (n * (n * n - 1) * dt * dt))


def paper_covariance(
    family: Literal["diverging", "parallel"],
    n: int,
    dt: float = 1.0,
    sigma2: float = 1.0,
    *,
    printed: bool = False,
) -> FloatArray:
    """Ψ* of two objects measured together at ``t_i = (i − 1)·dt``, ``i = 1..N``:
    (18) for the diverging family (θ = y0, V1, V2), (20) for the parallel one
    (θ = y01, y02, V).

    ``printed=True`` returns the matrices exactly as printed (with σ² restored in (18),
    whose second equality drops it); ``False`` the corrected ones. Corrections
    (C = dt·N(N−1)/2, D = dt²·N(N−1)(2N−1)/6 as in (17)):

    * (18): elements (2,1), (3,1) are −3/(dt·N(N+1)) (printed +); (2,3) and (3,2) are
      9/(dt²·N(N+1)(2N−1)) (printed 3/(dt·N(N+1)) and 3(5N−1)/(dt²·N(N+1)(2N−1)));
    * (20): element (1,2) is 3(N−1)/(2N(N+1)) (printed 3/(dt·N(N+1))).
    """
    where = "trajectories.paper_covariance"
    family = as_choice(f"{where} family", family, ("diverging", "parallel"))  # type: ignore
    n = as_count(f"{where} n", n, minimum=2)
    dt = as_positive(f"{where} dt", dt)
    sigma2 = as_positive(f"{where} sigma2", sigma2)
    as_flag(f"{where} printed", printed)
    nn, t = float(n), float(dt)
    k = 3 / (t * nn * (nn + 1))
    if family == "diverging":
        d0 = (2 * nn - 1) / (nn * (nn + 1))
        dv = 3 * (5 * nn - 1) / (t * t * nn * (nn * nn - 1) * (2 * nn - 1))
        if printed:
            m = [
                [d0, -k, -k],
                [k, dv, k],
                [k, 3 * (5 * nn - 1) / (t * t * nn * (nn + 1) * (2 * nn - 1)), dv],
            ]
        else:
            c = 9 / (t * t * nn * (nn + 1) * (2 * nn - 1))
            m = [[d0, -k, -k], [-k, dv, c], [-k, c, dv]]
    elif family == "parallel":
        d0 = (5 * nn - 1) / (2 * nn * (nn + 1))
        dv = 6 / (t * t * nn * (nn * nn - 1))
        c01 = k if printed else 3 * (nn - 1) / (2 * nn * (nn + 1))
        m = [[d0, c01, -k], [3 * (nn - 1) / (2 * nn * (nn + 1)), d0, -k], [-k, -k, dv]]
    else:
        raise ProblemError(f"family: expected 'diverging' or 'parallel', got {family!r}")
    return sigma2 * np.array(m)


def eta0(q: int = 2) -> float:
    """The conclusions' ratio for the **shared** parameter (y0 of a diverging family, V of
    a parallel one): Var(shared, dependent LSQ) / Var(same parameter from one object's
    independent line), ``Q`` objects measured at the same times: 1/Q (printed 0.5 for
    Q = 2). It equals the gain of simply averaging the Q independent estimates."""
    q = as_count("trajectories.eta0 q", q, minimum=1)
    return 1.0 / q


def eta(n: int, q: int = 2) -> float:
    """The conclusions' ratio for the **unique** parameters (V_j of a diverging family,
    y0_j of a parallel one): Var(dependent LSQ) / Var(independent line), ``Q`` objects
    each measured at ``t_i = (i − 1)·ΔT``, ``i = 1..N`` (first measurement at the common
    start):

    η = 1 − r(1 − 1/Q),  r = (Σt)²/(N Σt²) = 3(N − 1)/(2(2N − 1));

    for Q = 2 this is the printed (5N − 1)/(4(2N − 1)) (0.7 at N = 3 → 0.625). A ratio
    of variances; the ratio of RMS errors is √η."""
    n = as_count("trajectories.eta n", n, minimum=2)
    q = as_count("trajectories.eta q", q, minimum=1)
    r = 3 * (n - 1) / (2 * (2 * n - 1))
    return 1.0 - r * (1.0 - 1.0 / q)


def variance_ratios(data: TrajectoryData, family: FamilyName | Family) -> dict[str, FloatArray]:
    """Var(start_j), Var(velocity_j) under the family divided by the same variances from
    object j's own independent line, for the data's actual times and variances: the
    general form of the conclusions' η and η0. Arrays (Q,) or (Q, d)."""
    as_instance("trajectories.variance_ratios data", data, TrajectoryData)
    fam = resolve_family(family, data.n_objects)
    q = data.n_objects
    dep = _fit(data, fam).cov
    ind = _fit(data, Family.independent(q)).cov
    dv = np.diagonal(dep, axis1=1, axis2=2)  # (d, R)
    iv = np.diagonal(ind, axis1=1, axis2=2)  # (d, 2Q)
    rs = dv[:, fam.start_index] / iv[:, :q]
    rv = dv[:, fam.velocity_index] / iv[:, q:]
    return {"start": _shape(data, rs.T), "velocity": _shape(data, rv.T)}
