r"""The problem of paper 004 in NumPy: the data, the model (5), (8) of a hypothesis
H = (π, γ) of (13)-(14) and its score (13), the objective every answer is re-checked
against.

Model (the paper leaves the group likelihood and the prior open; this is the default):

* object j predicted N(m_j, K_j); a measurement of it is N(x; m_j, K_j + K1) -- (5);
* an unresolved group S (|S| ≥ 2) gives one measurement at the members' mean:
  N(x; mean_{j∈S} m_j, Σ_{j∈S}K_j/|S|² + K1);
* background (clutter): 1/Δx -- (8);
* hypothesis H = (π, γ): every measurement goes to exactly one block of π or to the
  background, every block gets at most one measurement;
* ln P(H) = (Q − |π|) ln ρ + Σ_{S∈π}[d_S ln P_D + (1 − d_S) ln(1 − P_D)];
* score(H) = ln P(H) + Σ_i ln φ_{i,γ(i)}; the MAP hypothesis maximises it.

Holds: :class:`AssignmentData` (every argument checked), the likelihoods (5)
:func:`log_likelihoods` (the dense table, size guard :data:`MAX_TABLE_ENTRIES`) and
:func:`entry_log_likelihoods` (given entries only), the predicted returns
:func:`group_moments` / :func:`group_arrays`, the prior :func:`block_log_prior`, the
objective :func:`score` (13), and the validators :func:`_as_block`, :func:`_as_partition`,
:func:`_as_assignment`. The candidate groups are in :mod:`~optmodels.assignment.groups`,
the result type in :mod:`~optmodels.assignment.solution`, the re-check of an answer in
:mod:`~optmodels.assignment.verify`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sps

from optmodels.assignment.merge_prior import log_group_weight
from optmodels.assignment.sensor import (
    PAIR_NEGLECT,
    U_FLOOR,
    PairTable,
    Resolution,
    _dense_edges,
)
from optmodels.core import (
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_float_array,
    as_instance,
    as_positive,
    as_probability,
    check_spd_stack,
)

Partition = list[tuple[int, ...]]

#: Entries of a dense ln φ table refused by :func:`log_likelihoods` (8 bytes each: 2 GiB),
#: and the work memory (bytes) of one batch of Cholesky factors.
MAX_TABLE_ENTRIES = 2**28
_WORK_BYTES = 64 * 2**20
#: Groups per batch of the default likelihood (bounds the (groups, N, d, d) work arrays).
_CHUNK = 2048


# ----------------------------------------------------------------------------- data
@dataclass
class AssignmentData:
    """Predictions ``means`` (Q, d), ``covs`` (Q, d, d); ``measurements`` (N, d) with noise
    ``meas_cov``: one (d, d) for all or one per measurement (N, d, d), R_i (e.g. from
    :func:`~optmodels.assignment.polar.polar_measurement_covs`); surveillance ``volume``
    Δx (m^d); detection probability ``pd`` ∈ (0, 1); the merge prior: a per-merge factor
    ``rho`` ∈ (0, 1] (the paper's constant), or instead a ``sensor``
    (:class:`~optmodels.assignment.sensor.Resolution`: the prior of a group from its
    members' predicted separation and uncertainty, and the centroid weights; give one of
    ``rho`` and ``sensor``); candidate groups limited by ``max_group_size`` (default: all
    sizes) and ``group_gate`` (members pairwise within this Mahalanobis distance of each
    other's predictions, under K_i + K_j; default: no gate). Units SI: means and
    measurements in m (or the sensor's own units, the same for all), covariances in their
    square, Δx in m^d.

    Your own model: ``log_likelihood(data, S)`` → (N,) ln φ_iS for block S (replaces the
    Gaussian default), and ``block_log_prior(S, detected)`` → the block's share of ln P(H)
    (default (|S| − 1) ln ρ, or ln w(S) with a sensor, + ln P_D or ln(1 − P_D)). The prior
    must decompose over blocks for the MILP to stay linear. With a custom prior only the
    background-dominance pruning is applied."""

    means: FloatArray
    covs: FloatArray
    measurements: FloatArray
    meas_cov: FloatArray
    volume: float
    pd: float
    rho: float | None = None
    max_group_size: int | None = None
    group_gate: float | None = None
    log_likelihood: Callable[[AssignmentData, tuple[int, ...]], FloatArray] | None = None
    block_log_prior: Callable[[tuple[int, ...], bool], float] | None = None
    sensor: Resolution | None = None
    _pair_u: Any = field(default=None, init=False, repr=False, compare=False)
    _log_w: dict[tuple[int, ...], float] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _conn: dict[Any, float] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        w = "assignment.AssignmentData"
        self.means = as_finite_array(f"{w} means", self.means, ndim=2)
        q, d = self.means.shape
        if q < 1 or d < 1:
            raise ProblemError(
                f"{w} means: need at least one object with at least one "
                f"coordinate, got shape {self.means.shape}"
            )
        self.covs = as_finite_array(f"{w} covs", self.covs, shape=(q, d, d))
        check_spd_stack(f"{w} covs", self.covs)
        meas = self.measurements
        if (
            meas is not None
            and not isinstance(meas, str)
            and as_float_array(f"{w} measurements", meas).size == 0
        ):
            meas = np.zeros((0, d))
        self.measurements = as_finite_array(f"{w} measurements", meas, ndim=2)
        if self.measurements.shape[1] != d:
            raise ProblemError(
                f"{w} measurements: expected (N, {d}) like means, got {self.measurements.shape}"
            )
        n = self.measurements.shape[0]
        self.meas_cov = as_finite_array(f"{w} meas_cov", self.meas_cov, ndim=(2, 3))
        if self.meas_cov.shape not in ((d, d), (n, d, d)):
            raise ProblemError(
                f"{w} meas_cov: expected ({d}, {d}) or one per measurement "
                f"({n}, {d}, {d}), got {self.meas_cov.shape}"
            )
        check_spd_stack(f"{w} meas_cov", self.meas_cov)
        self.pd = as_probability(f"{w} pd", self.pd, low_open=True, high_open=True)
        # Δx (m^d, SI) enters through its logarithm: positive and finite. ρ is the prior
        # factor of one merge, P(H) ∝ ρ^(Q − |π|): in (0, 1] (ρ > 1 would make merged
        # variants a priori more likely than the resolved one)
        self.volume = as_positive(f"{w} volume", self.volume)
        if self.sensor is not None:
            as_instance(f"{w} sensor", self.sensor, Resolution)
            if self.rho is not None:
                raise ProblemError(
                    f"{w} rho: give rho (a constant merge prior) or sensor "
                    f"(the resolution model), not both"
                )
            if self.block_log_prior is not None:
                raise ProblemError(f"{w} sensor: give sensor or your own block_log_prior, not both")
            self.sensor._check(f"{w} sensor", d, q)
            if type(self.sensor).pair_probabilities is Resolution.pair_probabilities:
                # the model's own gate: only the pairs that can be unresolved (k-d tree)
                self._pair_u = PairTable(
                    q, *self.sensor._gated_pairs(f"{w} sensor", self.means, self.covs, PAIR_NEGLECT)
                )
            else:  # a subclass with its own (dense) pair model
                self._pair_u = np.asarray(self.sensor.pair_probabilities(self.means, self.covs))
        elif self.rho is None:
            raise ProblemError(
                f"{w} rho: required without a sensor (the constant merge prior, in (0, 1])"
            )
        else:
            self.rho = as_probability(f"{w} rho", self.rho, low_open=True)
        self._log_w, self._conn = {}, {}
        if self.max_group_size is not None:
            self.max_group_size = as_count(f"{w} max_group_size", self.max_group_size, minimum=1)
        if self.group_gate is not None:
            self.group_gate = as_positive(f"{w} group_gate", self.group_gate, allow_inf=True)
        for name in ("log_likelihood", "block_log_prior"):
            if getattr(self, name) is not None and not callable(getattr(self, name)):
                raise ProblemError(
                    f"{w} {name}: expected a callable or None, got "
                    f"{type(getattr(self, name)).__name__}"
                )

    @property
    def per_measurement_cov(self) -> bool:
        """True when ``meas_cov`` holds one covariance per measurement."""
        return self.meas_cov.ndim == 3

    @property
    def log_prior_constant(self) -> float:
        """C = Σ_{i<j} ln(1 − u_ij) with a sensor (0 without): ln P(π) = C + Σ_S ln w(S);
        :func:`score` leaves C out (it is the same for every hypothesis)."""
        if self._pair_u is None:
            return 0.0
        if isinstance(self._pair_u, PairTable):
            return self._pair_u.log_not_merged_total()
        return float(np.sum(np.log1p(-self._pair_u[np.triu_indices(self.q, 1)])))

    def pair_unresolved(self) -> FloatArray | None:
        """The sensor's pair probabilities u_ij (Q, Q), or None without a sensor; the
        neglected pairs (u_ij ≤ PAIR_NEGLECT, proven by the gate) read U_FLOOR. Refused
        (ProblemError) where the dense table would exceed 2 GiB: use :attr:`pair_table`."""
        if self._pair_u is None:
            return None
        if isinstance(self._pair_u, PairTable):
            return self._pair_u.dense("assignment.AssignmentData.pair_unresolved")
        return self._pair_u.copy()

    @property
    def pair_table(self) -> PairTable | None:
        """The gated pairs (i < j, u_ij) as a :class:`PairTable`, or None without a
        sensor (a sensor subclass's dense table is returned gated the same way)."""
        if self._pair_u is None or isinstance(self._pair_u, PairTable):
            return self._pair_u
        ii, jj = np.triu_indices(self.q, 1)
        on = self._pair_u[ii, jj] > U_FLOOR
        return PairTable(self.q, ii[on], jj[on], self._pair_u[ii[on], jj[on]])

    def pair_edges(self) -> tuple[np.ndarray, np.ndarray]:
        """The gating graph's edges: pairs (i < j) with u_ij > PAIR_NEGLECT (empty without
        a sensor)."""
        if self._pair_u is None:
            return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
        if isinstance(self._pair_u, PairTable):
            return self._pair_u.edges()
        return _dense_edges(self._pair_u)

    @property
    def q(self) -> int:
        return int(self.means.shape[0])

    @property
    def n(self) -> int:
        return int(self.measurements.shape[0])


# ----------------------------------------------------------------------------- likelihoods
def block_log_prior(data: AssignmentData, group: tuple[int, ...], detected: bool) -> float:
    """A block's share of ln P(H): the user's ``block_log_prior``, or with a sensor
    ln w(S) (:func:`~optmodels.assignment.merge_prior.log_group_weight`: ln P_conn(S) −
    Σ_{i<j∈S} ln(1 − u_ij); ln(u_ij/(1 − u_ij)) for a pair, 0 for a singleton), else the
    constant (|S| − 1) ln ρ; plus ln P_D if detected, else ln(1 − P_D)."""
    as_instance("assignment.block_log_prior data", data, AssignmentData)
    group = _as_block("assignment.block_log_prior group", group, data.q)
    if not isinstance(detected, bool | np.bool_):
        raise ProblemError(
            f"assignment.block_log_prior detected: expected True or False, got "
            f"{type(detected).__name__}"
        )
    if data.block_log_prior is not None:
        v = float(data.block_log_prior(tuple(group), bool(detected)))
        if not np.isfinite(v):
            raise ProblemError(f"block_log_prior: non-finite value for {group}, {detected}")
        return v
    det = math.log(data.pd) if detected else math.log1p(-data.pd)
    if data._pair_u is not None:
        g = tuple(group)
        lw = data._log_w.get(g)
        if lw is None:
            lw = data._log_w[g] = log_group_weight(data._pair_u, g, data._conn)
        return lw + det
    assert data.rho is not None, "AssignmentData checks: rho is required without a sensor"
    return (len(group) - 1) * math.log(data.rho) + det


def group_moments(data: AssignmentData, group: tuple[int, ...]) -> tuple[FloatArray, FloatArray]:
    """The predicted return of a block: centroid Σ w_j m_j and its covariance Σ w_j² K_j
    (without the measurement noise); weights equal or the sensor's amplitudes."""
    idx = list(group)
    if data.sensor is None or isinstance(data.sensor.weights, str):
        return data.means[idx].mean(axis=0), data.covs[idx].sum(axis=0) / len(idx) ** 2
    wts = data.sensor.centroid_weights(tuple(group))
    return wts @ data.means[idx], np.einsum("j,jab->ab", wts**2, data.covs[idx])


def log_likelihoods(data: AssignmentData, groups: Sequence[tuple[int, ...]]) -> FloatArray:
    """ln φ_iS (N, len(groups)): the user's ``log_likelihood`` or the default model
    N(x_i; Σ w_j m_j, Σ w_j² K_j + R_i) (5), R_i the measurement's own covariance."""
    as_instance("assignment.log_likelihoods data", data, AssignmentData)
    if isinstance(groups, str | bytes | dict) or not hasattr(groups, "__iter__"):
        raise ProblemError(
            f"assignment.log_likelihoods groups: expected a list of blocks, got "
            f"{type(groups).__name__}"
        )
    groups = [
        _as_block(f"assignment.log_likelihoods groups[{c}]", g, data.q)
        for c, g in enumerate(groups)
    ]
    out = np.empty((data.n, len(groups)))
    if data.log_likelihood is not None:
        for c, g in enumerate(groups):
            try:
                v = np.asarray(data.log_likelihood(data, tuple(g)), dtype=float)
            except (TypeError, ValueError) as exc:
                raise ProblemError(
                    f"log_likelihood: not a numeric array for block {g} ({exc})"
                ) from None
            if v.shape != (data.n,) or np.any(np.isnan(v)) or np.any(v == np.inf):
                raise ProblemError(
                    f"log_likelihood: expected {data.n} finite log values "
                    f"(or −inf) for block {g}, got shape {v.shape}"
                )
            out[:, c] = v
        return out
    if data.n * len(groups) > MAX_TABLE_ENTRIES:
        raise ProblemError(
            f"assignment.log_likelihoods: the N × groups table is {data.n} × "
            f"{len(groups)} = {data.n * len(groups):.3g} entries, above "
            f"{MAX_TABLE_ENTRIES:.0e} ({MAX_TABLE_ENTRIES * 8 / 2**30:.2g} GiB); "
            f"solve computes only the gated entries, or pass fewer groups"
        )
    if data.n:
        d = data.means.shape[1]
        per_group = data.n * d * (d + 4) * 8 * (2 if data.per_measurement_cov else 1)
        step = max(1, min(_CHUNK, _WORK_BYTES // max(1, per_group)))
        for start in range(0, len(groups), step):
            part = groups[start : start + step]
            out[:, start : start + len(part)] = _default_loglik(data, part).T
    return out


def entry_log_likelihoods(
    data: AssignmentData, groups: Sequence[tuple[int, ...]], rows: np.ndarray, cols: np.ndarray
) -> FloatArray:
    """ln φ_iS (5) of the entries (i = ``rows[k]``, S = ``groups[cols[k]]``) only, the
    default Gaussian model N(x_i; Σ w_j m_j, Σ w_j² K_j + R_i), batched in chunks of
    bounded work memory (the Cholesky factors of the entries' (d, d) covariances)."""
    d = data.means.shape[1]
    out = np.empty(len(rows))
    if not len(rows):
        return out
    mean, cov = group_arrays(data, groups)
    const = 0.5 * d * math.log(2 * math.pi)
    step = max(1, _WORK_BYTES // (8 * d * (d + 4) * 4))
    for a in range(0, len(rows), step):
        r, c = rows[a : a + step], cols[a : a + step]
        noise = data.meas_cov[r] if data.per_measurement_cov else data.meas_cov
        s2 = cov[c] + noise
        if d == 2:  # closed-form 2 × 2 (np.linalg's batched calls cost ~5x more, measured)
            det = s2[:, 0, 0] * s2[:, 1, 1] - s2[:, 0, 1] * s2[:, 1, 0]
            dx = data.measurements[r] - mean[c]
            m2 = (
                s2[:, 1, 1] * dx[:, 0] ** 2
                - (s2[:, 0, 1] + s2[:, 1, 0]) * dx[:, 0] * dx[:, 1]
                + s2[:, 0, 0] * dx[:, 1] ** 2
            ) / det
            out[a : a + step] = -0.5 * m2 - 0.5 * np.log(det) - const
            continue
        chol = np.linalg.cholesky(s2)
        z = np.linalg.solve(chol, (data.measurements[r] - mean[c])[..., None])[..., 0]
        logdet = np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
        out[a : a + step] = -0.5 * np.sum(z**2, axis=-1) - logdet - const
    return out


def group_arrays(
    data: AssignmentData, groups: Sequence[tuple[int, ...]]
) -> tuple[FloatArray, FloatArray]:
    """Every group's centroid Σ w_j m_j (G, d) and Σ w_j² K_j (G, d, d) (as
    :func:`group_moments`), batched per group size with NumPy (no sparse matrix: its
    construction alone costs ~0.3 ms, measured, a tenth of a small scan's budget)."""
    d = data.means.shape[1]
    sizes = np.fromiter(map(len, groups), dtype=int, count=len(groups))
    mean, cov = np.empty((len(groups), d)), np.empty((len(groups), d, d))
    amp = (
        None if data.sensor is None or isinstance(data.sensor.weights, str) else data.sensor.weights
    )
    for s_ in sorted(set(sizes.tolist())):
        at = np.flatnonzero(sizes == s_)
        mem = np.array([groups[c] for c in at.tolist()], dtype=int).reshape(len(at), s_)
        if s_ == 1:
            mean[at], cov[at] = data.means[mem[:, 0]], data.covs[mem[:, 0]]
            continue
        if amp is None:
            w = np.full(mem.shape, 1.0 / s_)
        else:
            w = amp[mem] / amp[mem].sum(axis=1, keepdims=True)
        mean[at] = np.einsum("gs,gsd->gd", w, data.means[mem])
        cov[at] = np.einsum("gs,gsab->gab", w**2, data.covs[mem])
    return mean, cov


def _group_matrix(data: AssignmentData, groups: Sequence[tuple[int, ...]]) -> sps.csr_matrix:
    """The centroid weights as a sparse (len(groups), Q) matrix (row S: w_j on S's
    members)."""
    rows = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    cols = np.fromiter((j for g in groups for j in g), dtype=int, count=len(rows))
    if data.sensor is None or isinstance(data.sensor.weights, str):
        vals = np.repeat([1.0 / len(g) for g in groups], [len(g) for g in groups])
    else:
        amp = data.sensor.weights
        sums = np.array([amp[list(g)].sum() for g in groups])
        vals = amp[cols] / sums[rows]
    return sps.csr_matrix((vals, (rows, cols)), shape=(len(groups), data.q))


def _default_loglik(data: AssignmentData, groups: Sequence[tuple[int, ...]]) -> FloatArray:
    """ln N(x_i; Σ w_j m_j, Σ w_j² K_j + R_i) (len(groups), N), batched over the groups
    (one Cholesky factor per group, or per group and measurement with R_i each)."""
    q, d = data.means.shape
    wm = _group_matrix(data, groups)
    mean = np.asarray(wm @ data.means)  # (G, d)
    cov = np.asarray(wm.power(2) @ data.covs.reshape(q, d * d)).reshape(-1, d, d)
    diff = data.measurements[None, :, :] - mean[:, None, :]  # (G, N, d)
    const = 0.5 * d * math.log(2 * math.pi)
    if data.per_measurement_cov:
        chol = np.linalg.cholesky(cov[:, None] + data.meas_cov[None])  # (G, N, d, d)
        z = np.linalg.solve(chol, diff[..., None])[..., 0]
        logdet = np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)  # (G, N)
    else:
        chol = np.linalg.cholesky(cov + data.meas_cov)  # (G, d, d)
        z = np.linalg.solve(chol, diff.transpose(0, 2, 1)).transpose(0, 2, 1)
        logdet = np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)[:, None]
    return -0.5 * np.sum(z**2, axis=-1) - logdet - const


def score(
    data: AssignmentData,
    partition: Partition,
    assignment: Sequence[int] | np.ndarray,
    loglik: dict[tuple[int, ...], FloatArray] | None = None,
) -> float:
    """score(H) of a hypothesis: ``assignment[i]`` indexes ``partition`` or is −1."""
    as_instance("assignment.score data", data, AssignmentData)
    blocks = _as_partition("assignment.score partition", partition, data.q)
    a = _as_assignment("assignment.score assignment", assignment, data.n, len(blocks))
    used = {k for k in a if k >= 0}
    s = math.fsum(block_log_prior(data, b, k in used) for k, b in enumerate(blocks))
    rows = np.array([i for i, k in enumerate(a) if k >= 0], dtype=int)
    if loglik is not None:
        vals = [float(loglik[blocks[a[i]]][i]) for i in rows]
    elif data.log_likelihood is not None:  # the user's model: one (N,) call per used block
        ub = sorted(used)
        table = dict(zip(ub, log_likelihoods(data, [blocks[k] for k in ub]).T, strict=True))
        vals = [float(table[a[i]][i]) for i in rows]
    else:  # the default model on the assigned entries only
        vals = entry_log_likelihoods(
            data, blocks, rows, np.array([a[i] for i in rows], dtype=int)
        ).tolist()
    return s + math.fsum(vals) - (data.n - len(rows)) * math.log(data.volume)


def _as_block(name: str, group: Any, q: int) -> tuple[int, ...]:
    """``group`` as a non-empty tuple of distinct object indices in 0..Q−1 (a block)."""
    if (
        isinstance(group, tuple)
        and group
        and all(
            isinstance(j, int | np.integer) and not isinstance(j, bool) and 0 <= j < q
            for j in group
        )
        and len(set(group)) == len(group)
    ):
        return group  # the fast path of the solvers' own calls
    if isinstance(group, str | bytes | dict) or not hasattr(group, "__iter__"):
        raise ProblemError(
            f"{name}: expected a block (a tuple of object indices), got {type(group).__name__}"
        )
    try:
        block = tuple(as_count(f"{name} entry", j, maximum=q - 1) for j in group)
    except TypeError:
        raise ProblemError(f"{name}: expected a block (a tuple of object indices)") from None
    if not block or len(set(block)) != len(block):
        raise ProblemError(f"{name}: expected distinct object indices, at least one, got {block}")
    return block


def _as_partition(name: str, partition: Any, q: int) -> Partition:
    """``partition`` as sorted tuples of object indices that cover 0..Q−1 exactly once."""
    try:
        blocks = [
            tuple(sorted(as_count(f"{name} entry", j, maximum=q - 1) for j in b)) for b in partition
        ]
    except TypeError:
        raise ProblemError(
            f"{name}: expected a list of blocks (lists of object "
            f"indices), got {type(partition).__name__}"
        ) from None
    if any(not b for b in blocks) or sorted(j for b in blocks for j in b) != list(range(q)):
        raise ProblemError(
            f"{name}: must cover every object 0..{q - 1} exactly once with non-empty blocks"
        )
    return blocks


def _as_assignment(name: str, assignment: Any, n: int, blocks: int) -> list[int]:
    """``assignment`` as N block indices or −1, no block twice."""
    try:
        a = [as_count(f"{name} entry", k, minimum=-1, maximum=blocks - 1) for k in assignment]
    except TypeError:
        raise ProblemError(f"{name}: expected one block index or −1 per measurement") from None
    if len(a) != n:
        raise ProblemError(f"{name}: one entry per measurement ({n}), got {len(a)}")
    used = [k for k in a if k >= 0]
    if len(used) != len(set(used)):
        raise ProblemError(f"{name}: a block received more than one measurement")
    return a
