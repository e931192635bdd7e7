"""``optmodels montecarlo STUDY``: a seeded Monte Carlo study of :mod:`optmodels.montecarlo`
(local processes or a Dask cluster), resumed from a checkpoint, with its summary."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from optmodels.cli.args import _count
from optmodels.cli.contract import Outcome, _leaf, _out_file, _reading
from optmodels.core import ProblemError, json_document
from optmodels.execution import scheduler_argument


def _montecarlo(args: argparse.Namespace) -> Outcome:
    """``montecarlo``: exit 1 when a trial's solve failed (``SolveError``; the checkpoint
    keeps the finished trials) or a per-trial value is not finite."""
    from optmodels import montecarlo as mc
    from optmodels.io import write_json

    params: dict[str, Any] = {}
    for item in args.param or []:
        key, sep, val = item.partition("=")
        if not sep or not key:
            raise ProblemError(f"--param: expected NAME=VALUE, got {item!r}")
        try:  # a JSON value (the one strict reader: no NaN, no key given twice) or text
            params[key] = json_document(val, where=f"--param {key}")
        except ProblemError:
            if val.lstrip().startswith(("{", "[")):  # meant as JSON: say what is wrong
                raise
            params[key] = val
    with _reading("--param"):
        study = mc.study(args.study, **params)
    checkpoint = _out_file("--checkpoint", args.checkpoint) if args.checkpoint else None
    out_path = _out_file("--out", args.out) if args.out else None
    res = mc.run(
        study,
        args.trials,
        args.seed,
        scheduler=args.scheduler,
        checkpoint=checkpoint,
        workers=args.workers,
        progress=not args.json,
        retry_failed=args.retry_failed,
    )
    out = {
        "study": res.study,
        "seed": res.seed,
        "trials": int(res.trials.size),
        "requested": res.requested,
        "n_ok": res.n_ok,
        "failed": len(res.failures),
        "failures": [[int(i), str(m)] for i, m in res.failures[:20]],
        "skipped_lines": res.skipped_lines,
        "resumed": res.resumed,
        "engine": res.engine,
        "summary": res.summary,
        "means": {k: res.mean(k) for k in res.values},
        "standard_errors": {k: res.se(k) for k in res.values} if res.n_ok > 1 else {},
        "units": _units(study, [*res.summary, *res.values]),
    }
    out["out"] = str(out_path.resolve()) if out_path is not None else None
    out["checkpoint"] = str(checkpoint.resolve()) if checkpoint is not None else None
    if out_path is not None:
        write_json(out_path, {**out, "values": res.values})
    finite = all(bool(np.all(np.isfinite(np.asarray(v, dtype=float)))) for v in res.values.values())
    return out, finite and not res.failures


def _units(study: Any, keys: list[str]) -> dict[str, str]:
    """The unit of each value and summary entry, from the study's ``units`` (a key ending
    in digits, ``w0``, ``w1``, ..., is looked up as ``w#``); a key the study does not
    declare has none."""
    import re

    declared: dict[str, str] = dict(getattr(study, "units", None) or {})
    out = {}
    for k in keys:
        unit = declared.get(k) or declared.get(re.sub(r"\d+$", "#", k))
        if unit:
            out[k] = unit
    return out


def _print_montecarlo(res: dict[str, Any]) -> None:
    print(
        f"{res['study']}: {res['trials']} trials (seed {res['seed']}, {res['resumed']} "
        f"from the checkpoint), engine {res['engine']}"
    )
    for key, what in (("out", "values and summary"), ("checkpoint", "checkpoint")):
        if res.get(key):
            print(f"  wrote {res[key]} ({what})")
    if res["failed"]:
        print(
            f"  {res['failed']} of {res['requested']} trials failed (recorded; "
            "--retry-failed runs them again), e.g."
        )
        for i, msg in res["failures"][:3]:
            print(f"    trial {i}: {msg}")
    if res["skipped_lines"]:
        print(f"  {res['skipped_lines']} unreadable checkpoint line(s) skipped")
    units = res.get("units", {})

    def unit(k: str) -> str:
        return f" {units[k]}" if k in units else ""

    for k, v in res["summary"].items():
        shown = f"{v:.6g}" if isinstance(v, int | float) else f"{v}"
        print(f"  {k:>22s} = {shown}{unit(k)}")
    for k, v in res["means"].items():
        se = res["standard_errors"].get(k)
        print(f"  mean {k:>17s} = {v:.6g}" + (f" ± {se:.2g}" if se is not None else "") + unit(k))


def register(sub: Any) -> None:
    """Add ``optmodels montecarlo`` to the top-level sub-commands ``sub``."""
    count0, count1 = _count(0), _count(1)

    mcp = _leaf(sub, "montecarlo", "run a seeded Monte Carlo study (local or Dask)")
    mcp.add_argument(
        "study",
        help="plane-angle, trajectories-eta, fusion-weight, "
        "biasfield-recovery, assignment-separation",
    )
    mcp.add_argument("--trials", type=count1, default=1000, help="trials to run (>= 1)")
    mcp.add_argument(
        "--seed", type=count0, default=0, help="seed of the study's numpy.random.Generator streams"
    )
    mcp.add_argument(
        "--param",
        action="append",
        metavar="NAME=VALUE",
        help="study parameter (repeatable), e.g. --param n=100",
    )
    mcp.add_argument(
        "--scheduler",
        type=scheduler_argument,
        default="processes",
        help="processes (default), serial, or a Dask address tcp://host:8786",
    )
    mcp.add_argument("--workers", type=count1, help="local processes (default: all cores)")
    mcp.add_argument(
        "--checkpoint", metavar="FILE", help="JSON-lines FILE; a rerun resumes from it"
    )
    mcp.add_argument(
        "--retry-failed",
        action="store_true",
        help="run again the trials the checkpoint records as failed",
    )
    mcp.add_argument(
        "--out", metavar="FILE", help="write the per-trial values and summary to this JSON FILE"
    )
    mcp.set_defaults(func=_montecarlo, printer=_print_montecarlo)
