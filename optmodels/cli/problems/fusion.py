"""``optmodels fusion weights``: the fusion weight W of paper 003 from two sample
covariances, its Jacobians P1, P2 (13)-(14) and the first-order Cov(vec W) (10); and the
fusion part of ``optmodels demo`` and ``optmodels compare --details``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.cli.args import _count
from optmodels.cli.contract import Outcome, _group, _leaf, _reading
from optmodels.core import ProblemError

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = (
    "- [Fusion of two estimates (paper 003)](fusion/report.md): accuracy of Ŵ "
    "vs n, the two-site system with the joint ML"
)


def _matrix_arg(flag: str, text: str) -> np.ndarray:
    """A matrix given inline as JSON (``'[[1,0],[0,2]]'``) or as a path to .npy/.json."""
    path = Path(text)
    try:
        if path.suffix == ".npy" and path.is_file():
            return np.asarray(np.load(path, allow_pickle=False), dtype=float)
        if path.suffix == ".json" and path.is_file():
            return np.asarray(json.loads(path.read_text(encoding="utf-8")), dtype=float)
        return np.asarray(json.loads(text), dtype=float)
    except (ValueError, TypeError, OSError) as exc:  # UnicodeDecodeError is a ValueError
        raise ProblemError(
            f"{flag}: expected a JSON matrix like '[[1,0],[0,2]]' or a path "
            f"to an existing .npy/.json file, got {text!r:.80} ({exc})"
        ) from None


def _fusion_weights(args: argparse.Namespace) -> Outcome:
    from optmodels import fusion

    s1, s2 = _matrix_arg("--s1", args.s1), _matrix_arg("--s2", args.s2)
    n1 = args.n1 if args.n1 is not None else args.n
    n2 = args.n2 if args.n2 is not None else args.n
    if n1 is None or n2 is None:
        raise ProblemError("--n: give the sample size (or --n1 and --n2)")
    try:
        with _reading("--s1/--s2"):
            w = fusion.weight_matrix(s1, s2)
    except ProblemError as exc:  # name the command-line flag, not the Python argument
        msg = str(exc)
        if msg.startswith("--"):
            raise
        flag = "--s2" if "S2" in msg.split(":")[0] or msg.startswith("S2") else "--s1"
        raise ProblemError(f"{flag}: {msg}") from None
    m = w.shape[0]
    try:
        s12 = _matrix_arg("--s12", args.s12) if args.s12 else None
        with _reading("--s12/--n"):
            cov = fusion.weight_covariance(s1, s2, n1, n2, mean=args.mean, s12=s12)
    except ProblemError as exc:  # n1/n2 -> the flag the user typed
        msg = str(exc)
        head = msg.split(":")[0]
        if msg.startswith("--"):
            raise
        if "s12" in head.lower():
            raise ProblemError(f"--s12: {msg}") from None
        which = "n2" if "n2" in head else "n1"
        flag = f"--{which}" if getattr(args, which) is not None else "--n"
        raise ProblemError(f"{flag}: {msg}") from None
    p1, p2 = fusion.weight_jacobians(s1, s2)
    return {
        "W": w,
        "P1": p1,
        "P2": p2,
        "cov_vec_W": cov,
        "std_W": np.sqrt(np.clip(np.diag(cov), 0, None)).reshape(m, m, order="F"),
        "n1": n1,
        "n2": n2,
        "mean": args.mean,
        "shared_snapshots": args.s12 is not None,
        "note": "vec stacks columns (12); Cov(vec W) is the first-order (10), "
        "accurate to a few per cent from n ~ 100 (docs/errata.md)",
    }, True


def _print_fusion_weights(res: dict[str, Any]) -> None:
    with np.printoptions(precision=6, suppress=False, linewidth=120):
        for key in ("W", "std_W", "P1", "P2", "cov_vec_W"):
            print(f"{key} =\n{res[key]}")
    print(f"n1 = {res['n1']}, n2 = {res['n2']}, mean = {res['mean']}; {res['note']}")


def run_demo(out: Path, args: argparse.Namespace, progress: bool) -> dict[str, Any]:
    """``optmodels demo``: the accuracy of Ŵ and the two-site study of paper 003 in
    ``out/fusion``."""
    from optmodels.demo import run_fusion_demo

    return run_fusion_demo(
        out / "fusion",
        trials=args.fusion_trials,
        positions=args.fusion_positions,
        seed=args.seed,
        progress=progress,
    )


def run_details(
    out: Path, *, sizes: list[int], runs: int, repeats: int, seed: int, progress: bool
) -> tuple[str, dict[str, Any]]:
    """``optmodels compare --details``: :mod:`solvers_cmp.fusion`'s rows and benchmark;
    the report section and the result entry."""
    from solvers_cmp import fusion as cmp_fusion

    rows = cmp_fusion.rows(seed=seed, repeats=max(1, min(repeats, 3)), progress=progress)
    bench = cmp_fusion.benchmark(repeats=repeats, seed=seed)
    md = cmp_fusion.write_report(out, rows, bench)
    return md, {"results": rows, "benchmark": bench}


def register(sub: Any) -> None:
    """Add ``optmodels fusion weights`` to the top-level sub-commands ``sub``."""
    count1 = _count(1)
    fsub = _group(sub, "fusion", "fusion of two estimates (paper 003)")
    fw = _leaf(fsub, "weights", "W, the Jacobians P1, P2 (13)-(14) and Cov(vec W) (10)")
    fw.add_argument(
        "--s1",
        required=True,
        help="error covariance of estimate 1: JSON '[[..],[..]]' or .npy/.json path",
    )
    fw.add_argument("--s2", required=True, help="error covariance of estimate 2 (as --s1)")
    fw.add_argument("--n", type=count1, help="snapshots behind both sample covariances")
    fw.add_argument("--n1", type=count1, help="snapshots behind S1 (overrides --n)")
    fw.add_argument("--n2", type=count1, help="snapshots behind S2 (overrides --n)")
    fw.add_argument(
        "--mean",
        choices=("sample", "known"),
        default="sample",
        help="sample covariances about the sample mean, or about the known "
        "mean (the paper's literal (3))",
    )
    fw.add_argument(
        "--s12",
        help="Cov(a1, a2) when both sample covariances come from the "
        "same snapshots of correlated estimators (adds the cross "
        "block to (10); needs n1 = n2)",
    )
    fw.set_defaults(func=_fusion_weights, printer=_print_fusion_weights)
