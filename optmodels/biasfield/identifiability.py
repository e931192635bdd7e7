r"""What the data identify in section 4 (paper 001): how firmly the smoothness criterion
(9) pins the field down on the sets (10) -- the condition of H = Φ¹ᵀRΦ¹ and the per-cell
spread from the diagonal blocks of H⁻¹ (see ``docs/formulations.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import linalg as splinalg

from optmodels.biasfield.fielddata import FieldData, uncertainty_sets
from optmodels.biasfield.problem import check_graph, r_matrix
from optmodels.core import FloatArray, ProblemError, as_count

__all__ = ["Identifiability", "identifiability"]


@dataclass(frozen=True)
class Identifiability:
    """How well the smoothness criterion pins the field down.

    ``condition``: condition number of H = Φ¹ᵀRΦ¹ (2K × 2K); ``spread`` (K,):
    √tr of the 2 × 2 diagonal blocks of H⁻¹ per cell (metres per unit √J: how far η_k,
    the per-cell common shift, can move for a given rise of J); ``worst``: cells by
    decreasing spread. What no method can recover: the common Cartesian shift in each cell
    (η_k itself) is fixed only by the smoothness prior, never by the data.
    """

    condition: float
    spread: FloatArray
    worst: np.ndarray


def identifiability(data: FieldData, *, batch: int = 512) -> Identifiability:
    """Condition of Φ¹ᵀRΦ¹ (sparse eigenvalues) and the per-cell spread from the diagonal
    blocks of its inverse (one sparse factorisation, solved in batches of columns)."""
    batch = as_count("biasfield.identifiability batch", batch, minimum=1)
    check_graph(data)
    _, phi1 = uncertainty_sets(data)
    h = (phi1.T @ r_matrix(data) @ phi1).tocsc()
    try:
        lu = splinalg.splu(h)
    except RuntimeError as exc:
        raise ProblemError(
            f"biasfield.identifiability data: Φ1ᵀRΦ1 is singular ({exc}); "
            "the field is not identifiable on these cells"
        ) from None
    n = h.shape[0]
    diag = np.empty((n // 2, 2, 2))
    for start in range(0, n, batch):
        cols = np.arange(start, min(start + batch, n))
        rhs = np.zeros((n, cols.size))
        rhs[cols, np.arange(cols.size)] = 1.0
        x = lu.solve(rhs)
        for c_i, c in enumerate(cols):
            diag[c // 2, :, c % 2] = x[2 * (c // 2) : 2 * (c // 2) + 2, c_i]
    spread = np.sqrt(np.maximum(np.trace(diag, axis1=1, axis2=2), 0.0))
    lam_max = float(splinalg.eigsh(h, k=1, which="LA", return_eigenvectors=False)[0])
    inv_max = float(
        splinalg.eigsh(
            splinalg.LinearOperator(h.shape, matvec=lu.solve, dtype=float),
            k=1,
            which="LA",
            return_eigenvectors=False,
        )[0]
    )
    return Identifiability(lam_max * inv_max, spread, np.argsort(-spread))
