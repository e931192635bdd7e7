r"""Soft association with merged measurements (issue 29): the posterior over the joint
hypotheses H = (π, γ) of paper 004 (13)-(14), turned into marginal association
probabilities per object, exactly per cluster (``docs/formulations.md``, "Soft
association with merged measurements").

Model: the package's (:mod:`~optmodels.assignment.data`: the likelihoods (5) with each
measurement's own covariance R_i, the centroid model of a merged group, clutter 1/Δx (8),
the merge prior: constant ρ or the sensor's resolution model w(S)), with the gating of a
probabilistic data association filter as two optional keywords: a measurement may come
from block S only when its Mahalanobis distance to S's predicted return (under
Σ w_j² K_j + R_i) is at most ``gate``, and an undetected block has the prior
1 − P_D P_G (``prob_gate`` P_G; Stone Soup's ``PDAHypothesiser`` convention). With
``gate=None`` and ``prob_gate=1`` the posterior is exactly P(H | z) ∝ exp(score(H)) of
(13).

P(H | z) ∝ Π_{S∈π} w(S) · Π_{S detected by i} P_D φ_iS Δx · Π_{S undetected}(1 − P_D P_G)
(the clutter factor of every measurement divided out), so the marginals per object j are

* β_j(S, i): P(j's block is S and S produced measurement i) — S = (j,): a resolved
  detection; |S| ≥ 2: the merged detection i shared with the other members of S;
* β_j(S, −1): P(j's block is S and S is undetected) (the miss; for |S| ≥ 2 a merged miss).

Exactness: the pairs (i, S) whose posterior mass is provably below ``prune`` (each: the
ratio P_D φ_iS Δx / (1 − P_D P_G) of the hypothesis to its copy with i in the clutter) and
the merged groups that are provably negligible (their weight relative to the undetected
singletons, times N + 1 preimages) are dropped, and the sum of those bounds is reported
(``pruned_bound``: the neglected posterior mass, relative). The rest splits into the
connected components (clusters) of the graph joining the members of a kept group and the
objects sharing a kept measurement; the posterior factorises over clusters, each is
enumerated when it has at most ``max_enumerated`` hypotheses, else its ``k`` best are
taken from :func:`~optmodels.assignment.kbest.k_best` with its bound on the neglected mass
(``KBest.neglected``).

Holds :class:`SoftMarginals`, :func:`soft_marginals`, :func:`effective_gate` and
:func:`reduce_mixture`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.special import gammainc

from optmodels.assignment.data import (
    AssignmentData,
    block_log_prior,
    group_moments,
    log_likelihoods,
)
from optmodels.assignment.groups import candidate_groups
from optmodels.core import (
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_instance,
    as_positive,
    as_probability,
    check_spd,
)

__all__ = [
    "SoftMarginals",
    "chi2_gate_probability",
    "effective_gate",
    "reduce_mixture",
    "soft_marginals",
]

#: A cluster with more hypotheses than this is not enumerated (k-best instead).
MAX_ENUMERATED = 20_000

Block = tuple[int, ...]


@dataclass(frozen=True)
class SoftMarginals:
    """Marginal association probabilities (module docstring).

    ``beta[j]`` maps (block S ∋ j, measurement i or −1) to the posterior probability;
    ``clusters`` the object sets of the clusters (``cluster_of[j]`` indexes them),
    ``cluster_measurements`` their measurements, ``methods`` per cluster
    ("single", "enumeration" or "k_best"), ``hypotheses`` the hypotheses weighed per
    cluster, ``neglected`` per cluster the bound on the neglected posterior mass relative
    to the weighed (0 when enumerated), ``pruned_bound`` the bound on the mass of the
    pruned pairs and groups (relative to the total), and ``bound`` a bound on every
    marginal's absolute error: max_c ε_c/(1 + ε_c) + pruned_bound/(1 − pruned_bound)."""

    beta: list[dict[tuple[Block, int], float]]
    clusters: list[tuple[int, ...]]
    cluster_of: list[int]
    cluster_measurements: list[tuple[int, ...]]
    methods: list[str]
    hypotheses: list[int]
    neglected: list[float]
    pruned_bound: float
    gate: float | None = None
    prob_gate: float = 1.0
    info: dict[str, float] = field(default_factory=dict)

    @property
    def bound(self) -> float:
        eps = max((e / (1.0 + e) if np.isfinite(e) else 1.0 for e in self.neglected), default=0.0)
        p = self.pruned_bound
        return eps + (p / (1.0 - p) if p < 1.0 else math.inf)

    def miss(self, j: int) -> float:
        """P(object j undetected), resolved or in a merged block."""
        return float(sum(v for (_, i), v in self.beta[j].items() if i < 0))

    def merged(self, j: int) -> float:
        """P(object j's block is merged, detected or not)."""
        return float(sum(v for (s, _), v in self.beta[j].items() if len(s) > 1))


def effective_gate(
    innovation_cov: FloatArray, pd: float, clutter_density: float, prob_gate: float = 1.0
) -> float:
    """The Mahalanobis distance d* at which a lone measurement's association probability
    is 1/2 (the soft gate): P_D N(z; ẑ, S)/λ = 1 − P_D P_G, i.e.

    d*² = 2 ln(P_D / ((1 − P_D P_G) λ (2π)^{d/2} √det S)) (0 when negative).

    The MAP (hard decision) takes a lone measurement exactly when d < d* (the issue's
    ≈ 3.7σ "gate"); the soft update weighs it by 1/(1 + e^{(d² − d*²)/2}) instead, inside
    the hard gate (``gate``), so a measurement beyond d* still pulls the track and widens
    its covariance by the spread of the mixture.

    Parameters
    ----------
    innovation_cov : (d, d) S = H P Hᵀ + R, m².
    pd, clutter_density : P_D in (0, 1) and λ (m⁻ᵈ).
    prob_gate : P_G in (0, 1].
    """
    s = as_finite_array("assignment.effective_gate innovation_cov", innovation_cov, ndim=2)
    pd = as_probability("assignment.effective_gate pd", pd, low_open=True, high_open=True)
    lam = as_positive("assignment.effective_gate clutter_density", clutter_density)
    pg = as_probability("assignment.effective_gate prob_gate", prob_gate, low_open=True)
    d = s.shape[0]
    check_spd("assignment.effective_gate innovation_cov", s)
    logdet = float(np.linalg.slogdet(s)[1])
    v = 2.0 * (
        math.log(pd)
        - math.log1p(-pd * pg)
        - math.log(lam)
        - 0.5 * d * math.log(2 * math.pi)
        - 0.5 * logdet
    )
    return math.sqrt(max(v, 0.0))


def chi2_gate_probability(gate: float, d: int) -> float:
    """P(χ²_d ≤ gate²): the gate probability P_G of a Mahalanobis gate."""
    return float(gammainc(0.5 * d, 0.5 * float(gate) ** 2))


def reduce_mixture(
    weights: FloatArray, means: FloatArray, covs: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Moment-matched single Gaussian of a mixture (JPDA's reduction; Stone Soup's
    ``gm_reduce_single``): weights (M,) ≥ 0, means (M, n), covs (M, n, n) →
    mean Σ w_m x_m, covariance Σ w_m (P_m + (x_m − x̄)(x_m − x̄)ᵀ), w normalised."""
    fn = "assignment.reduce_mixture"
    w = as_finite_array(f"{fn} weights", weights, ndim=1)
    x = as_finite_array(f"{fn} means", means, shape=(w.shape[0], None))
    p = as_finite_array(f"{fn} covs", covs, shape=(w.shape[0], x.shape[1], x.shape[1]))
    if w.size == 0 or np.any(w < 0) or not w.sum() > 0:
        raise ProblemError(f"{fn} weights: expected M ≥ 1 weights ≥ 0 with a positive sum")
    w = w / w.sum()
    mean = w @ x
    dx = x - mean
    cov = np.einsum("m,mab->ab", w, p) + np.einsum("m,ma,mb->ab", w, dx, dx)
    return mean, 0.5 * (cov + cov.T)


def _mahalanobis2(data: AssignmentData, groups: Sequence[Block]) -> FloatArray:
    """d²_iS (N, G) of each measurement to each block's predicted return under
    Σ w_j² K_j + R_i."""
    n, d = data.n, data.means.shape[1]
    out = np.empty((n, len(groups)))
    r = data.meas_cov if data.per_measurement_cov else np.broadcast_to(data.meas_cov, (n, d, d))
    for c, g in enumerate(groups):
        m, k = group_moments(data, g)
        diff = data.measurements - m
        out[:, c] = np.einsum(
            "na,na->n", diff, np.linalg.solve(k[None] + r, diff[..., None])[..., 0]
        )
    return out


class _Union:
    def __init__(self, n: int) -> None:
        self.p = list(range(n))

    def find(self, a: int) -> int:
        while self.p[a] != a:
            self.p[a] = self.p[self.p[a]]
            a = self.p[a]
        return a

    def join(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.p[max(ra, rb)] = min(ra, rb)


def soft_marginals(
    data: AssignmentData,
    *,
    gate: float | None = None,
    prob_gate: float = 1.0,
    prune: float = 1e-14,
    max_enumerated: int = MAX_ENUMERATED,
    k: int = 100,
    solver: str = "HIGHS",
) -> SoftMarginals:
    """Marginal association probabilities per object (module docstring).

    Parameters
    ----------
    data : AssignmentData
        The scan (paper 004's model, any merge prior, one R or R_i each).
    gate : float, optional
        Hard gate: the largest Mahalanobis distance of a measurement to a block's
        predicted return (None: no gate, every pair possible).
    prob_gate : float
        P_G in (0, 1]: an undetected block has the prior 1 − P_D P_G (1: the package's
        model (13); Stone Soup's PDAHypothesiser: its ``prob_gate``).
    prune : float
        Drop a pair or a merged group whose provable posterior mass is below this
        (the sum of the dropped bounds is ``pruned_bound``); 0 keeps everything.
    max_enumerated : int
        Enumerate a cluster with at most this many hypotheses; above, its ``k`` best
        (:func:`~optmodels.assignment.kbest.k_best`, MILPs by ``solver``).

    Raises
    ------
    ProblemError
        Bad arguments; a user ``block_log_prior`` with ``prob_gate`` < 1.
    """
    w = "assignment.soft_marginals"
    as_instance(f"{w} data", data, AssignmentData)
    if gate is not None:
        gate = as_positive(f"{w} gate", gate, allow_inf=True)
    pg = as_probability(f"{w} prob_gate", prob_gate, low_open=True)
    prune = float(as_probability(f"{w} prune", prune))
    max_enumerated = as_count(f"{w} max_enumerated", max_enumerated, minimum=1)
    k = as_count(f"{w} k", k, minimum=1)
    if data.block_log_prior is not None and pg < 1.0:
        raise ProblemError(
            f"{w} prob_gate: with your own block_log_prior give "
            f"prob_gate = 1 (put the gate into the prior)"
        )
    q, n = data.q, data.n
    groups = candidate_groups(data, model_gate=False)  # its own pruning bounds every group
    ll = log_likelihoods(data, groups) if n else np.zeros((0, len(groups)))
    p1 = np.array([block_log_prior(data, g, True) for g in groups])
    p0 = np.array([block_log_prior(data, g, False) for g in groups])
    if pg < 1.0:
        p0 = p0 - math.log1p(-data.pd) + math.log1p(-data.pd * pg)
    a = ll + (p1 - p0)[None, :] + math.log(data.volume)  # pair vs its clutter copy
    allowed = np.isfinite(a)
    if gate is not None and np.isfinite(gate) and n:
        allowed &= _mahalanobis2(data, groups) <= gate**2
    log_prune = math.log(prune) if prune > 0 else -math.inf
    with np.errstate(over="ignore"):
        drop = allowed & (a < log_prune)
        pruned = float(np.sum(np.exp(a[drop]))) if drop.any() else 0.0
    single = {g[0]: c for c, g in enumerate(groups) if len(g) == 1}
    keep_g = np.ones(len(groups), dtype=bool)
    for c, g in enumerate(groups):
        if len(g) < 2:
            continue
        best = float(np.max(a[allowed[:, c], c], initial=0.0))
        lr = p0[c] - sum(p0[single[j]] for j in g) + max(best, 0.0) + math.log(n + 1)
        if lr < log_prune:
            keep_g[c] = False
            pruned += math.exp(lr)
    usable = allowed & ~drop & keep_g[None, :]
    # clusters: members of a kept group, objects sharing a usable measurement
    uf = _Union(q)
    for c in np.flatnonzero(keep_g).tolist():
        for j in groups[c][1:]:
            uf.join(groups[c][0], j)
    for i in range(n):
        near = {j for c in np.flatnonzero(usable[i]).tolist() for j in groups[c]}
        if len(near) > 1:
            it = iter(near)
            first = next(it)
            for j in it:
                uf.join(first, j)
    roots: dict[int, int] = {}
    cluster_of = [roots.setdefault(uf.find(j), len(roots)) for j in range(q)]
    clusters = [tuple(j for j in range(q) if cluster_of[j] == c) for c in range(len(roots))]
    g_of: list[list[int]] = [[] for _ in clusters]
    for c in np.flatnonzero(keep_g).tolist():
        g_of[cluster_of[groups[c][0]]].append(int(c))
    beta: list[dict[tuple[Block, int], float]] = [{} for _ in range(q)]
    meas_of, methods, counts, neglected = [], [], [], []
    for ci, objs in enumerate(clusters):
        cols = g_of[ci]
        meas = tuple(int(i) for i in np.flatnonzero(usable[:, cols].any(axis=1)))
        meas_of.append(meas)
        hyps = _enumerate(
            objs,
            [groups[c] for c in cols],
            p0[cols],
            [[(int(i), float(a[i, c])) for i in np.flatnonzero(usable[:, c])] for c in cols],
            max_enumerated,
        )
        if hyps is not None:
            methods.append("single" if len(objs) == 1 else "enumeration")
            eps = 0.0
        else:
            hyps, eps = _k_best_cluster(
                data,
                objs,
                meas,
                [groups[c] for c in cols],
                p0[cols],
                p1[cols],
                ll[:, cols],
                usable[:, cols],
                k,
                solver,
            )
            methods.append("k_best")
        lw = np.array([h[0] for h in hyps])
        wt = np.exp(lw - lw.max())
        wt /= wt.sum()
        for wh, (_, blocks) in zip(wt, hyps, strict=True):
            for s, i in blocks:
                for j in s:
                    beta[j][(s, i)] = beta[j].get((s, i), 0.0) + float(wh)
        counts.append(len(hyps))
        neglected.append(eps)
    return SoftMarginals(
        beta,
        clusters,
        cluster_of,
        meas_of,
        methods,
        counts,
        neglected,
        pruned,
        gate,
        pg,
        {
            "candidate_groups": float(len(groups)),
            "kept_groups": float(keep_g.sum()),
            "pairs": float(usable.sum()),
        },
    )


def _enumerate(
    objs: tuple[int, ...],
    groups: list[Block],
    p0: FloatArray,
    pairs: list[list[tuple[int, float]]],
    limit: int,
) -> list[tuple[float, list[tuple[Block, int]]]] | None:
    """Every hypothesis of one cluster: (log weight, [(block, measurement or −1)]), the
    log weight Σ_S [p0(S) + a_iS if detected by i]; None beyond ``limit`` hypotheses."""
    by_first: dict[int, list[int]] = {}
    for c, g in enumerate(groups):
        by_first.setdefault(g[0], []).append(c)
    order = list(objs)
    out: list[tuple[float, list[tuple[Block, int]]]] = []

    def rec(
        pos: int,
        covered: frozenset[int],
        used: frozenset[int],
        lw: float,
        blocks: list[tuple[Block, int]],
    ) -> bool:
        while pos < len(order) and order[pos] in covered:
            pos += 1
        if pos == len(order):
            out.append((lw, list(blocks)))
            return len(out) <= limit
        j = order[pos]
        for c in by_first.get(j, []):
            g = groups[c]
            if any(m in covered for m in g):
                continue
            cov = covered | set(g)
            blocks.append((g, -1))
            if not rec(pos + 1, cov, used, lw + p0[c], blocks):
                return False
            blocks.pop()
            for i, ai in pairs[c]:
                if i in used:
                    continue
                blocks.append((g, i))
                if not rec(pos + 1, cov, used | {i}, lw + p0[c] + ai, blocks):
                    return False
                blocks.pop()
        return True

    return out if rec(0, frozenset(), frozenset(), 0.0, []) else None


def _k_best_cluster(
    data: AssignmentData,
    objs: tuple[int, ...],
    meas: tuple[int, ...],
    groups: list[Block],
    p0: FloatArray,
    p1: FloatArray,
    ll: FloatArray,
    usable: np.ndarray,
    k: int,
    solver: str,
) -> tuple[list[tuple[float, list[tuple[Block, int]]]], float]:
    """The k best hypotheses of one cluster (:func:`~optmodels.assignment.kbest.k_best`
    on the cluster's sub-problem: its objects and usable measurements, the kept groups
    with their priors, the other groups impossible) and the bound on the neglected mass."""
    from optmodels.assignment.kbest import k_best

    local = {j: b for b, j in enumerate(objs)}
    index = {tuple(local[j] for j in g): c for c, g in enumerate(groups)}
    mrows = list(meas)
    table = np.where(usable[mrows], ll[mrows], -np.inf)

    def lik(_: AssignmentData, s: Block) -> FloatArray:
        c = index.get(tuple(s))
        return np.full(len(mrows), -np.inf) if c is None else table[:, c]

    def prior(s: Block, detected: bool) -> float:
        c = index.get(tuple(s))
        if c is None:
            return -1e4  # not a kept group: impossible in effect (e^-1e4 = 0)
        return float(p1[c] if detected else p0[c])

    rc = data.meas_cov[mrows] if data.per_measurement_cov else data.meas_cov
    sub = AssignmentData(
        data.means[list(objs)],
        data.covs[list(objs)],
        data.measurements[mrows],
        rc,
        volume=data.volume,
        pd=data.pd,
        rho=1.0,
        max_group_size=max(len(g) for g in groups),
        log_likelihood=lik,
        block_log_prior=prior,
    )
    kb = k_best(sub, k, solver=solver)
    out = []
    for h in kb.hypotheses:
        blocks = []
        det = {int(b): mrows[i] for i, b in enumerate(h.assignment) if b >= 0}
        for b, blk in enumerate(h.partition):
            blocks.append((tuple(objs[x] for x in blk), det.get(b, -1)))
        # log weight in this module's convention: score + N ln Δx (the clutter divided out)
        out.append((float(h.log_score) + len(mrows) * math.log(data.volume), blocks))
    return out, float(kb.neglected)
