"""The original problem of paper 002 in NumPy: the model values, the weighted least-squares
objective W (1), (4), (10) of Q lines, the violation of the family's equalities, and the
design matrix A (2), (5), (11).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from optmodels.core import FloatArray, ProblemError, as_finite_array, as_instance
from optmodels.trajectories.data import Family, FamilyName, TrajectoryData, resolve_family
from optmodels.trajectories.moments import _stats


# --------------------------------------------------------------------------- original form
def _per_object(data: TrajectoryData, a: ArrayLike, name: str) -> FloatArray:
    arr = as_finite_array(name, a)
    if arr.size != data.n_objects * data.dim:
        raise ProblemError(f"{name}: expected ({data.n_objects}, {data.dim}), got {arr.shape}")
    return arr.reshape(data.n_objects, data.dim)


def predict(data: TrajectoryData, start: ArrayLike, velocity: ArrayLike) -> FloatArray:
    """Model values ŷ = start_j + velocity_j (t − epoch) at the data's times, (Σ N_j, d)."""
    as_instance("trajectories.predict data", data, TrajectoryData)
    s = _per_object(data, start, "trajectories.predict start")
    v = _per_object(data, velocity, "trajectories.predict velocity")
    return s[data.obj] + v[data.obj] * data.t[:, None]


def objective(data: TrajectoryData, start: ArrayLike, velocity: ArrayLike) -> float:
    """W (4), (10) of the Q lines, weighted: Σ w (y − y0_j − V_j (t − epoch))², evaluated
    in centred times (y − p_j − V_j (t − T_j), p_j = y0_j + V_j (T_j − epoch))."""
    as_instance("trajectories.objective data", data, TrajectoryData)
    s = _per_object(data, start, "trajectories.objective start")
    v = _per_object(data, velocity, "trajectories.objective velocity")
    st = _stats(data)
    p = s + v * st.u
    r = st.ry + (st.p - p)[data.obj] - v[data.obj] * st.tau
    return float(np.sum(data.w * r * r))


def constraint_residuals(
    data: TrajectoryData, family: FamilyName | Family, start: ArrayLike, velocity: ArrayLike
) -> dict[str, float]:
    """Largest violation of the family's equalities (y0_j = y0_k, V_j = V_k in a group),
    relative to the size of the parameters."""
    as_instance("trajectories.constraint_residuals data", data, TrajectoryData)
    fam = resolve_family(family, data.n_objects)
    s = _per_object(data, start, "trajectories.constraint_residuals start")
    v = _per_object(data, velocity, "trajectories.constraint_residuals velocity")
    out = {}
    for key, arr, groups in (("start", s, fam.start_groups), ("velocity", v, fam.velocity_groups)):
        worst = 0.0
        scale = max(float(np.max(np.abs(arr))), 1.0)
        for g in groups:
            if len(g) > 1:
                worst = max(worst, float(np.max(np.abs(arr[list(g)] - arr[g[0]]))) / scale)
        out[f"shared_{key}"] = worst
    return out


def design_matrix(data: TrajectoryData, family: FamilyName | Family) -> sp.csr_matrix:
    """The design matrix A (2) of the family, rows object by object: (5) for diverging,
    (11) for parallel (returned as A, the paper prints Aᵀ). Sparse, Σ N_j × R, velocity
    columns t − epoch (s)."""
    as_instance("trajectories.design_matrix data", data, TrajectoryData)
    fam = resolve_family(family, data.n_objects)
    n = data.n_measurements
    rows = np.concatenate([np.arange(n), np.arange(n)])
    cols = np.concatenate([fam.start_index[data.obj], fam.velocity_index[data.obj]])
    vals = np.concatenate([np.ones(n), data.t])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, fam.n_params))
