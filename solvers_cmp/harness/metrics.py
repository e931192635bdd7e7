"""Summary metrics of a sweep: shifted geometric means (qpbenchmark), their bootstrap
intervals, the per (problem, formulation, solver) summary and the headline ranking with
ties (issue 27, item 2).

Every summary row carries ``kind``: ``original`` (a generic solve of the problem as the
paper states it), ``reduction`` (a reduced formulation, or a special case such as the
linear assignment without merges) or ``reference`` (the closed form or the exact
enumeration: the floor). The headline ranks ``original`` rows only, per problem.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

#: Shift of the shifted geometric means, s (qpbenchmark's 10 ms).
SHIFT = 0.01
#: Bootstrap resamples and level of the intervals.
N_BOOT = 2000
LEVEL = 0.95


def shifted_geometric_mean(times: Iterable[float], shift: float = SHIFT) -> float:
    """exp(mean log(t + shift)) − shift (qpbenchmark; shift 10 ms keeps sub-millisecond
    times from dominating)."""
    t = np.asarray(list(times), dtype=float)
    if t.size == 0:
        return float("nan")
    return float(np.exp(np.mean(np.log(t + shift))) - shift)


def sgm_interval(
    times: Sequence[float],
    *,
    shift: float = SHIFT,
    n_boot: int = N_BOOT,
    level: float = LEVEL,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile bootstrap interval (``level``) of the shifted geometric mean of
    ``times`` (s), resampling the cases with replacement (seeded: the same data give the
    same interval). One time: a zero-width interval."""
    t = np.log(np.asarray(times, dtype=float) + shift)
    if t.size == 0:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, t.size, (n_boot, t.size))
    boot = np.exp(t[idx].mean(axis=1)) - shift
    a = (1 - level) / 2
    return float(np.quantile(boot, a)), float(np.quantile(boot, 1 - a))


def formulation_kind(problem: str, formulation: str) -> str:
    """``reference``, ``reduction`` or ``original`` for a row, from its adapter's
    ``reference_formulations`` / ``reductions`` (a problem without an adapter: only
    ``closed_form`` is a reference)."""
    if formulation == "closed_form":
        return "reference"
    try:
        from solvers_cmp import cases as cs

        ad = cs.adapter(problem)
    except Exception:  # a row of a problem no longer registered
        return "original"
    if formulation in getattr(ad, "reference_formulations", ()):
        return "reference"
    if formulation in getattr(ad, "reductions", ()):
        return "reduction"
    return "original"


#: Paired ratios to the leader below this are ties whatever their interval: the
#: run-to-run spread of a solver's ratio to the leader on this shared 2-core machine
#: (issue 27: two quick sweeps 45 min apart, load 0.7 and 10; over the 27 solvers with
#: every run successful in both the ratio moved by a median 1.22x, by up to 1.73x for 90 %
#: of them) -- a difference smaller than the machine's own noise is not a ranking.
TIE_MARGIN = 1.75


def _case_key(r: dict[str, Any]) -> tuple[Any, ...]:
    return (r.get("instance"), r.get("size"), r.get("seed"))


def _total(r: dict[str, Any], time_limit: float) -> float:
    """Build + solve of a successful row (the closed form: its solve); a failure is
    charged ``time_limit``."""
    if not r["success"]:
        return time_limit
    if r["formulation"] == "closed_form":
        return float(r["solve_time"])
    return float(r["solve_time"]) + float(r["build_time"])


def efficiency(rows: Sequence[dict[str, Any]]) -> tuple[float, int]:
    """Statistical efficiency of a solver's estimates (issue 27, item 6): over the rows
    that carry an estimate error against the truth (``estimate_sq_error``, the squared
    error of one seeded Monte Carlo draw, in the adapter's units) and its Cramér–Rao bound
    (``crb``, the bound on the expected squared error, same units),
    ``Σ crb / Σ estimate_sq_error`` and the number of draws. 1 for an efficient estimator
    (up to the Monte Carlo spread of the draws, which every solver of the problem shares:
    the same draws), below 1 for one that pays for an early stop; NaN without draws."""

    def num(v: Any) -> float:
        try:
            return float(v)
        except (TypeError, ValueError):
            return float("nan")

    pairs = [(num(r.get("estimate_sq_error")), num(r.get("crb"))) for r in rows]
    pairs = [(e, c) for e, c in pairs if np.isfinite(e) and np.isfinite(c)]
    if not pairs:
        return float("nan"), 0
    err = sum(e for e, _ in pairs)
    bound = sum(c for _, c in pairs)
    return (bound / err if err > 0 else float("inf")), len(pairs)


def summarise(
    rows: Sequence[dict[str, Any]],
    time_limit: float,
    *,
    n_boot: int = N_BOOT,
    seed: int = 0,
    skipped: Sequence[dict[str, Any]] = (),
) -> list[dict[str, Any]]:
    """Per (problem, formulation, solver): runs, success rate, shifted geometric means of
    solve and build time (failures charged ``time_limit``) and of their sum ``total``
    with its bootstrap interval (``sgm_total_lo``/``_hi``, over the cases), each also
    normalised to the best of its problem, worst error and violation among successes,
    the statistical efficiency (:func:`efficiency`: ``efficiency``, ``draws``),
    ``kind`` and, for the ``original`` rows, ``rank`` within (problem, formulation) with
    the paired ratio to the leader and its interval (``ratio_to_best``, ``_lo``, ``_hi``;
    :func:`rank_rows`). ``skipped``: runs the quick sweep left out as too slow (problem,
    instance, size, formulation, solver): each counts as a failure, so that a solver is
    never ranked on its easy cases only."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["problem"], r["formulation"], r["solver"]), []).append(r)
    for k in skipped:
        groups.setdefault((k["problem"], k["formulation"], k["solver"]), []).append(
            {**k, "success": False, "seed": k.get("seed"), "skipped": True}
        )
    # a case that another solver of the same (problem, formulation) ran but this one
    # did not (left out, or a sweep with --solvers on part of the cases) counts as its
    # failure too: every solver of a ranking is measured on the same cases
    forms: dict[tuple[str, str], set[tuple[Any, ...]]] = {}
    for (problem, form, _), rs in groups.items():
        forms.setdefault((problem, form), set()).update(_case_key(r) for r in rs)
    for (problem, form, solver), rs in groups.items():
        have = {_case_key(r) for r in rs}
        for c in sorted(forms[(problem, form)] - have, key=str):
            rs.append(
                {
                    "problem": problem,
                    "formulation": form,
                    "solver": solver,
                    "instance": c[0],
                    "size": c[1],
                    "seed": c[2],
                    "success": False,
                    "skipped": True,
                }
            )
    out = []
    per_case: dict[tuple[str, str, str], dict[tuple[Any, ...], float]] = {}
    for (problem, form, solver), rs in groups.items():
        succ = [r for r in rs if r["success"]]
        solve = [r["solve_time"] if r["success"] else time_limit for r in rs]
        build = [r["build_time"] if r["success"] else time_limit for r in rs]
        total = [_total(r, time_limit) for r in rs]
        per_case[(problem, form, solver)] = {
            _case_key(r): t for r, t in zip(rs, total, strict=True)
        }
        lo, hi = sgm_interval(total, n_boot=n_boot, seed=seed)
        eff, draws = efficiency([r for r in rs if not r.get("skipped")])
        out.append(
            {
                "problem": problem,
                "kind": formulation_kind(problem, form),
                "formulation": form,
                "solver": solver,
                "runs": len(rs),
                "skipped": sum(bool(r.get("skipped")) for r in rs),
                "success_rate": len(succ) / len(rs),
                "sgm_solve_time": shifted_geometric_mean(solve),
                "sgm_build_time": shifted_geometric_mean(build),
                "sgm_total_time": shifted_geometric_mean(total),
                "sgm_total_lo": lo,
                "sgm_total_hi": hi,
                "max_error": max((r["solution_error"] for r in succ), default=float("nan")),
                "max_violation": max((r["max_violation"] for r in succ), default=float("nan")),
                "efficiency": eff,
                "draws": draws,
            }
        )
    for problem in {o["problem"] for o in out}:
        mine = [o for o in out if o["problem"] == problem]
        for key in ("sgm_solve_time", "sgm_build_time", "sgm_total_time"):
            best = min(o[key] for o in mine) + SHIFT
            for o in mine:
                o[key.replace("sgm", "rel")] = (o[key] + SHIFT) / best
        # an original formulation per sub-problem (fusion: WLS, min-trace W, ML are
        # three problems): ranks within (problem, formulation), paired over its cases
        for form in {o["formulation"] for o in mine if o["kind"] == "original"}:
            grp = [o for o in mine if o["kind"] == "original" and o["formulation"] == form]
            cases = sorted(
                {c for o in grp for c in per_case[(problem, form, o["solver"])]}, key=str
            )
            logs = {
                o["solver"]: np.log(
                    np.array(
                        [per_case[(problem, form, o["solver"])].get(c, time_limit) for c in cases]
                    )
                    + SHIFT
                )
                for o in grp
            }
            rank_rows(grp, paired=_paired_boot(logs, n_boot, seed))
    order = {"original": 0, "reduction": 1, "reference": 2}
    out.sort(
        key=lambda o: (
            o["problem"],
            order[o["kind"]],
            o["formulation"],
            o.get("rank", 0),
            -o["success_rate"],
            o["sgm_total_time"],
        )
    )
    return out


def _paired_boot(logs: dict[str, np.ndarray], n_boot: int, seed: int) -> dict[str, np.ndarray]:
    """Per solver, the bootstrap means of log(total + shift) over the *same* resampled
    cases for every solver (a paired bootstrap: the spread of case difficulty -- sizes
    that differ 10× -- cancels in the ratios)."""
    n = len(next(iter(logs.values()))) if logs else 0
    if n == 0:
        return {}
    idx = np.random.default_rng(seed).integers(0, n, (n_boot, n))
    return {k: v[idx].mean(axis=1) for k, v in logs.items()}


def rank_rows(
    rows: list[dict[str, Any]],
    *,
    paired: dict[str, np.ndarray] | None = None,
    margin: float = TIE_MARGIN,
) -> list[dict[str, Any]]:
    """Rank rows of one (problem, original formulation) in place: by success rate, then
    ``sgm_total_time``; rank 1 is the leader and every row *tied* with it.

    With ``paired`` (per solver, the paired bootstrap means of log(total + shift),
    :func:`_paired_boot`): a row is tied with the first row of the current rank when
    their success rates are equal and the 95 % interval of its time ratio to that row,
    (t + shift)/(t_head + shift), reaches below ``margin`` (the machine's run-to-run
    noise, :data:`TIE_MARGIN`); each row gets ``ratio_to_best`` and its interval
    ``ratio_lo``/``ratio_hi`` against the leader. Without ``paired`` (summaries of rows
    without cases): tied when the intervals [``sgm_total_lo``, ``sgm_total_hi``]
    overlap. Ranks are competition ranks (the next rank is the row's position);
    ``tied=True`` marks every row of a rank with two or more rows."""
    rows.sort(key=lambda o: (-o["success_rate"], o["sgm_total_time"]))
    a = (1 - LEVEL) / 2

    def ratio(o: dict[str, Any], ref: dict[str, Any]) -> tuple[float, float, float]:
        assert paired is not None
        d = paired[o["solver"]] - paired[ref["solver"]]
        # (the same cases for both: the ratio of their shifted means, exactly)
        mid = (o["sgm_total_time"] + SHIFT) / (ref["sgm_total_time"] + SHIFT)
        return mid, float(np.exp(np.quantile(d, a))), float(np.exp(np.quantile(d, 1 - a)))

    def tied(o: dict[str, Any], ref: dict[str, Any]) -> bool:
        if o["success_rate"] != ref["success_rate"]:
            return False
        if paired is not None and o["solver"] in paired and ref["solver"] in paired:
            return ratio(o, ref)[1] <= margin
        return _overlap(ref, o)

    head: dict[str, Any] | None = None  # the first row of the current rank
    for i, o in enumerate(rows):
        o["tied"] = False
        if paired is not None and rows[0]["solver"] in paired and o["solver"] in paired:
            o["ratio_to_best"], o["ratio_lo"], o["ratio_hi"] = ratio(o, rows[0])
        if head is not None and tied(o, head):
            o["rank"] = head["rank"]
            o["tied"] = head["tied"] = True
        else:
            o["rank"] = i + 1
            head = o
    return rows


def _overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return (
        a["success_rate"] == b["success_rate"]
        and a["sgm_total_lo"] <= b["sgm_total_hi"]
        and b["sgm_total_lo"] <= a["sgm_total_hi"]
    )


def headline(summary: Sequence[dict[str, Any]]) -> dict[str, tuple[str, ...]]:
    """Per problem and original formulation (``"problem: formulation"``), the rows of
    rank 1 (the winner and every row tied with it), as sorted solver names: what a rerun
    must reproduce."""
    out: dict[str, list[str]] = {}
    for o in summary:
        if o["kind"] == "original" and o.get("rank") == 1:
            out.setdefault(f"{o['problem']}: {o['formulation']}", []).append(o["solver"])
    return {p: tuple(sorted(v)) for p, v in out.items()}
