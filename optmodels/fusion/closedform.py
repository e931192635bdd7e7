"""The paper's closed forms of the fusion (paper 003), the ``method="closed_form"`` of
:func:`optmodels.fusion.fuse`: the weight W (2), (6) with the fused covariance
(C1 + C2)⁻¹ = (I − W)S1, the fused estimate a1 + W(a2 − a1) (1)-(2), and for correlated
estimates the Bar-Shalom-Campo weight (S1 − S12)D⁺. Each answer is re-checked and gated by
:mod:`optmodels.fusion.verify` (:func:`~optmodels.fusion.verify._finish_independent`,
:func:`~optmodels.fusion.verify._finish_correlated`).

The paper's closed form has no function of its own in the API (the registry card's
``closed_form`` is ``None``): it is ``fuse(..., method="closed_form")``, and the W and
covariance it reports are those of the generic solve too.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optmodels.core import FloatArray, Status, timed
from optmodels.fusion.weights import _correlated_weight, _weight


def _paper_weight(s1: FloatArray, s2: FloatArray) -> tuple[FloatArray, FloatArray]:
    """W = S1(S1 + S2)⁻¹ (2), (6) and the fused covariance (C1 + C2)⁻¹ = (I − W)S1
    (symmetrised), for checked SPD S1, S2."""
    w = _weight(s1, s2)
    cov = (np.eye(s1.shape[0]) - w) @ s1
    return w, 0.5 * (cov + cov.T)


def _closed_form(
    x1: FloatArray, x2: FloatArray, w: FloatArray
) -> tuple[FloatArray, dict[str, Any]]:
    """The fused estimate (1)-(2), a1 + W(a2 − a1), and the solution's common fields
    (status OPTIMAL before the re-check, the time spent)."""
    with timed() as tm:
        est = x1 + w @ (x2 - x1)
    common: dict[str, Any] = {
        "status": Status.OPTIMAL,
        "method": "closed_form",
        "solve_time": tm.elapsed,
        "message": "(1)-(2)",
    }
    return est, common


def _closed_form_correlated(
    s1: FloatArray, s12: FloatArray, d: FloatArray
) -> tuple[FloatArray, dict[str, Any]]:
    """The weight of the best linear unbiased fusion of correlated estimates,
    W = (S1 − S12)D⁺ (Bar-Shalom-Campo; D = Cov(a1 − a2)), and the common fields."""
    with timed() as tm:
        w = _correlated_weight(s1, s12, d)
    common: dict[str, Any] = {
        "status": Status.OPTIMAL,
        "method": "closed_form",
        "solve_time": tm.elapsed,
        "message": "Bar-Shalom-Campo",
    }
    return w, common
