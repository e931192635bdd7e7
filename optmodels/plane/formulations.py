r"""The CasADi formulations of the plane problem (paper 000), with the data as parameters:
``"full"``, the original problem (1.2)-(1.3) in all 3N + 4 unknowns (:func:`_full_problem`),
with its Jacobian of (1.3) and Hessian of the Lagrangian written out in O(N)
(:func:`_full_derivatives`), and ``"reduced"``, (1.12)-(1.13) in ``(n, a)``
(:func:`_reduced_problem`). They are symbolic only: :mod:`optmodels.plane.generic` builds
them in the back-end's NLP cache (:func:`~optmodels.plane.generic.cached_nlp`) and solves
them.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from optmodels.core import FloatArray

#: Upper-triangle index pairs of a symmetric 3x3 matrix, the order used for parameters.
_IU = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _upper(mats: FloatArray) -> FloatArray:
    """(N, 3, 3) symmetric → (6, N) upper-triangle entries in :data:`_IU` order."""
    return np.stack([mats[:, j, k] for j, k in _IU])


def _full_problem(n: int) -> dict[str, Any]:
    """(1.2)-(1.3) as a CasADi NLP with the data as parameters.

    Unknowns: ``vec(X)`` (3N, columns x_i), ``n`` (3), ``a``. Parameters: ``vec(X*)``
    (3N) and the upper triangles of :math:`D_i^{-1}` (6N).
    """
    x = ca.MX.sym("x", 3, n)
    nv = ca.MX.sym("n", 3)
    a = ca.MX.sym("a")
    p_pts = ca.MX.sym("xs", 3, n)
    p_w = ca.MX.sym("Dinv", 6, n)
    e = x - p_pts
    f: Any = 0
    for r, (j, k) in enumerate(_IU):
        f = f + (1.0 if j == k else 2.0) * ca.dot(p_w[r, :], e[j, :] * e[k, :])
    g = ca.vertcat((ca.mtimes(nv.T, x) - a).T, ca.dot(nv, nv) - 1.0)
    return {
        "x": ca.vertcat(ca.vec(x), nv, a),
        "f": f / n,  # (1.2) / N: an O(1) objective, so IPOPT's tolerances are meaningful
        "g": g,
        "p": ca.vertcat(ca.vec(p_pts), ca.vec(p_w)),
    }


def _full_derivatives(n: int) -> dict[str, ca.Function]:
    r"""The Jacobian of (1.3) and the Hessian of the Lagrangian of :func:`_full_problem`,
    written out with their sparsity, in O(N) time and memory.

    Why not CasADi's: every row of (1.3) contains ``n`` and ``a``, so the Jacobian has four
    dense columns (and the Hessian three dense rows/columns, :math:`\partial^2/\partial
    x_i \partial n`); CasADi's generation of these two functions (sparsity detection and
    colouring for the automatic differentiation) costs O(N²) on such columns: 0.4 s at
    N = 5000, 1.2 s at 10⁴, 5.4 s at 2·10⁴ (``ca.nlpsol``, measured), against 0.1 s at
    2·10⁴ here. The matrices themselves have 7N + 3 and 9N + 3 (upper triangle)
    non-zeros:

    * :math:`\partial g_i/\partial x_i = n^T`, :math:`\partial g_i/\partial n = x_i^T`,
      :math:`\partial g_i/\partial a = -1`; :math:`\partial g_{N+1}/\partial n = 2 n^T`;
    * :math:`\partial^2 L/\partial x_i^2 = 2\sigma D_i^{-1}/N` (:math:`\sigma` the
      objective's multiplier), :math:`\partial^2 L/\partial x_i \partial n = \lambda_i
      I`, :math:`\partial^2 L/\partial n^2 = 2\lambda_{N+1} I`, nothing in ``a``.

    Same variables, parameters and order as :func:`_full_problem`, the signatures of
    CasADi's ``nlp_jac_g`` / ``nlp_hess_l`` (same sparsity and values; checked by
    ``tests/test_plane.py``).
    """
    x = ca.MX.sym("x", 3 * n + 4)
    p = ca.MX.sym("p", 9 * n)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", n + 1)
    pts = ca.reshape(x[: 3 * n], 3, n)
    nv = x[3 * n : 3 * n + 3]
    a = x[3 * n + 3]
    w = ca.reshape(p[3 * n :], 6, n)
    g = ca.vertcat((ca.mtimes(nv.T, pts) - a).T, ca.dot(nv, nv) - 1.0)
    # Jacobian, compressed columns: x_i^k -> row i; n_k -> rows 0..N; a -> rows 0..N-1.
    colind = np.concatenate(
        [np.arange(3 * n + 1), 3 * n + (n + 1) * np.arange(1, 4), [3 * n + 3 * (n + 1) + n]]
    )
    rows = np.concatenate([np.repeat(np.arange(n), 3), *[np.arange(n + 1)] * 3, np.arange(n)])
    jac = ca.MX(
        ca.Sparsity(n + 1, 3 * n + 4, colind.tolist(), rows.tolist()),
        ca.vertcat(
            ca.repmat(nv, n, 1),
            pts[0, :].T,
            2 * nv[0],
            pts[1, :].T,
            2 * nv[1],
            pts[2, :].T,
            2 * nv[2],
            -ca.DM.ones(n),
        ),
    )
    # Hessian, upper triangle, compressed columns: column k of block i holds rows
    # 3i..3i+k; column n_k holds rows 3i+k (i < N) and its diagonal.
    blk_rows = (3 * np.arange(n)[:, None] + np.array([0, 0, 1, 0, 1, 2])).ravel()
    blk_colind = (6 * np.arange(n)[:, None] + np.array([0, 1, 3])).ravel()
    hrows = np.concatenate(
        [blk_rows, *[np.append(3 * np.arange(n) + k, 3 * n + k) for k in range(3)]]
    )
    hcolind = np.concatenate([blk_colind, 6 * n + (n + 1) * np.arange(4), [6 * n + 3 * (n + 1)]])
    order = [_IU.index(jk) for jk in ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))]
    lam, mu2 = lam_g[:n], 2 * lam_g[n]
    hess = ca.MX(
        ca.Sparsity(3 * n + 4, 3 * n + 4, hcolind.tolist(), hrows.tolist()),
        ca.vertcat(ca.vec(w[order, :]) * (2.0 * lam_f / n), lam, mu2, lam, mu2, lam, mu2),
    )
    return {
        "jac_g": ca.Function("nlp_jac_g", [x, p], [g, jac], ["x", "p"], ["g", "jac_g_x"]),
        "hess_lag": ca.Function(
            "nlp_hess_l",
            [x, p, lam_f, lam_g],
            [hess],
            ["x", "p", "lam_f", "lam_g"],
            ["triu_hess_gamma_x_x"],
        ),
    }


def _reduced_problem(n: int) -> dict[str, Any]:
    """(1.12)-(1.13) as a CasADi NLP in (n, a) with the data as parameters.

    Parameters: ``vec(X*)`` (3N) and the upper triangles of :math:`D_i` (6N).
    """
    nv = ca.MX.sym("n", 3)
    a = ca.MX.sym("a")
    p_pts = ca.MX.sym("xs", 3, n)
    p_d = ca.MX.sym("D", 6, n)
    resid = a - ca.mtimes(nv.T, p_pts)
    den: Any = 0
    for r, (j, k) in enumerate(_IU):
        den = den + (1.0 if j == k else 2.0) * nv[j] * nv[k] * p_d[r, :]
    return {
        "x": ca.vertcat(nv, a),
        "f": ca.sum2(resid * resid / den) / n,  # (1.12) / N, O(1) as above
        "g": ca.dot(nv, nv) - 1.0,
        "p": ca.vertcat(ca.vec(p_pts), ca.vec(p_d)),
    }
