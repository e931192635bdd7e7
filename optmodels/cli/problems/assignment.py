"""``optmodels assignment solve`` (the MAP hypothesis of paper 004 for a CASE.json: one
MILP, enumeration (13)-(14), or the linear assignment without merges; the k best with
marginals) and ``optmodels assignment count`` (the number of hypotheses (14)); and the
assignment part of ``optmodels demo`` and ``optmodels compare --details``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from optmodels.cli.args import _count, _positive
from optmodels.cli.contract import _OK_STATUSES, Outcome, _group, _leaf, _reading
from optmodels.core import ProblemError, json_document

#: This problem's line in the demo's report/index.md.
DEMO_TITLE = (
    "- [Joint assignment with unresolved groups (paper 004)]"
    "(assignment/report.md): MAP by one MILP vs resolved-only "
    "association, closely spaced space objects"
)


#: ``hypotheses_total`` (and the dense ``pair_unresolved``) are reported up to this Q, N.
COUNTED = 400

_CASE_FIELDS = (
    "means",
    "covs",
    "measurements",
    "meas_cov",
    "volume",
    "pd",
    "rho",
    "max_group_size",
    "group_gate",
    "sensor",
)
#: Required in every case; ``rho`` too unless a ``sensor`` block is given (then not).
_REQUIRED = ("means", "covs", "measurements", "meas_cov", "volume", "pd")
_SENSOR_KEYS = ("range", "azimuth_deg", "site", "ellipse", "weights")


def _read_case(path_text: str) -> dict[str, Any]:
    """``CASE.json``: a JSON object with the :class:`AssignmentData` fields (``sensor``: a
    JSON object, read by :func:`_sensor`)."""
    from optmodels.io import read_text

    with _reading(path_text):
        text = read_text(path_text, what="JSON assignment case", name="case")
        case = json_document(text, where=path_text)  # the one strict reader
    if not isinstance(case, dict):
        raise ProblemError(
            f"{path_text}: expected a JSON object with the fields "
            f"{', '.join(_CASE_FIELDS[:7])}, got a JSON "
            f"{type(case).__name__.replace('NoneType', 'null')}"
        )
    unknown = sorted(set(case) - set(_CASE_FIELDS))
    if unknown:
        raise ProblemError(f"{path_text}: unknown fields {unknown} (expected {_CASE_FIELDS})")
    required = _REQUIRED if case.get("sensor") is not None else (*_REQUIRED, "rho")
    missing = sorted(set(required) - set(case))
    if missing:
        raise ProblemError(
            f"{path_text}: missing fields {missing}"
            + (" (or a sensor block instead of rho)" if "rho" in missing else "")
        )
    if case.get("sensor") is not None:
        case["sensor"] = _sensor(path_text, case["sensor"])
    return case


def _sensor(path_text: str, block: Any) -> Any:
    """The case's ``sensor`` block as a :class:`~optmodels.assignment.sensor.Resolution`:
    ``{"range": m, "azimuth_deg": deg, "site": [x, y]}`` (polar cell; site default the
    origin) or ``{"ellipse": [[m², ...], ...]}``, each with an optional ``weights``
    ("equal" or one positive amplitude per object)."""
    import math

    from optmodels.assignment.sensor import Resolution
    from optmodels.core import as_number

    where = f"{path_text}: sensor"
    if not isinstance(block, dict):
        raise ProblemError(
            f"{where}: expected a JSON object with range and azimuth_deg, or "
            f"ellipse; got a JSON {type(block).__name__}"
        )
    unknown = sorted(set(block) - set(_SENSOR_KEYS))
    if unknown:
        raise ProblemError(f"{where}: unknown keys {unknown} (expected {_SENSOR_KEYS})")
    az = block.get("azimuth_deg")
    if az is not None:
        az = math.radians(as_number(f"{where} azimuth_deg", az))
    with _reading(where):
        return Resolution(
            range=block.get("range"),
            azimuth=az,
            site=block.get("site"),
            ellipse=block.get("ellipse"),
            weights=block.get("weights", "equal"),
        )


def _assignment_solve(args: argparse.Namespace) -> Outcome:
    from optmodels import assignment as asg

    case = _read_case(args.case)
    with _reading(args.case):
        data = asg.AssignmentData(**case)
    # the count is a report (exact big integers, 0.2 s at Q = N = 400): given up to
    # COUNTED, null beyond; the solve's own limits guard its real cost
    total = asg.count_hypotheses(data.q, data.n) if max(data.q, data.n) <= COUNTED else None
    if args.method == "milp":
        sol = asg.solve(data, solver=args.solver, time_limit=args.time_limit)
    elif args.method == "brute-force":
        if total is None or total > 10_000_000:
            shown = f"{total:.3g}" if total is not None else f"Q = {data.q}, N = {data.n}: far"
            raise ProblemError(
                f"--method brute-force: {shown} hypotheses (more than 10⁷); use milp"
            )
        sol = asg.brute_force(data)
    else:
        sol = asg.linear_assignment(data)
    res: dict[str, Any] = {
        "status": sol.status.value,
        "method": sol.method,
        "message": sol.message,
        "partition": sol.partition,
        "assignment": sol.assignment,
        "log_score": sol.log_score,
        "mip_gap": sol.mip_gap,
        "solve_time": sol.solve_time,
        "build_time": sol.build_time,
        "hypotheses_total": total,
    }
    if data.sensor is not None:
        if data.q <= COUNTED:
            res["pair_unresolved"] = data.pair_unresolved()
        else:  # the dense table would be Q² numbers: the pairs that can be unresolved
            table = data.pair_table
            assert table is not None  # a sensor model is given (the branch's condition)
            res["pair_unresolved"] = None
            res["unresolved_pairs"] = [
                [int(a), int(b), float(u)]
                for a, b, u in zip(table.ii, table.jj, table.u, strict=True)
            ]
    if args.k and sol.ok:
        kb = asg.k_best(data, args.k, solver=args.solver)
        res["k_best"] = [
            {"partition": h.partition, "assignment": h.assignment, "log_score": h.log_score}
            for h in kb.hypotheses
        ]
        res["marginals"] = [
            {("background" if not k else ",".join(map(str, k))): v for k, v in b.items()}
            for b in kb.beta
        ]
        res["neglected_mass_bound"] = kb.neglected
    return res, sol.ok


def _big(n: int) -> str:
    """A count for the text: as is up to 15 digits, else ``≈ 1.234568e+1301 (log10
    1301.0915)`` (``assignment count 500 500`` has over 1000 digits; JSON keeps the exact
    integer)."""
    import math

    if n < 10**15:
        return str(n)
    lg = math.log10(n)
    return f"≈ {10 ** (lg - math.floor(lg)):.6f}e+{math.floor(lg)} (log10 {lg:.4f})"


def _marks(partition: list[list[int]], assignment: list[int]) -> str:
    """``m0 → 0, m1 → 1+2, m2 → background``: each measurement's block of objects."""
    blocks = ["+".join(map(str, b)) for b in partition]
    return (
        ", ".join(
            f"m{i} → {'background' if a < 0 else blocks[a]}" for i, a in enumerate(assignment)
        )
        or "(no measurement)"
    )


def _print_assignment_solve(res: dict[str, Any]) -> None:
    total = res["hypotheses_total"]
    print(
        f"{res['method']}: {res['status']}"
        + (f" ({res['message']})" if res["message"] else "")
        + f"; log score {res['log_score']:.6f}; "
        + (
            f"{_big(total)} hypotheses in total"
            if total is not None
            else "hypotheses not counted (Q or N above " + str(COUNTED) + ")"
        )
    )
    if res["status"] not in _OK_STATUSES:
        return
    blocks = ["+".join(map(str, b)) for b in res["partition"]]
    print("blocks: " + ", ".join(blocks))
    for i, a in enumerate(res["assignment"]):
        print(f"  measurement {i}: {'background' if a < 0 else blocks[a]}")
    if "k_best" in res:
        print(
            f"{len(res['k_best'])} best hypotheses (log score: each measurement's objects); "
            f"neglected mass ≤ {res['neglected_mass_bound']:.3g} of the listed:"
        )
        for r, h in enumerate(res["k_best"], start=1):
            print(f"  {r}. {h['log_score']:.6f}: {_marks(h['partition'], h['assignment'])}")


def _assignment_count(args: argparse.Namespace) -> Outcome:
    from optmodels import assignment as asg

    per = asg.count_per_variant(args.q, args.n)
    return {
        "q": args.q,
        "n": args.n,
        "total": asg.count_hypotheses(args.q, args.n),
        "variants": sum(v[0] for v in per.values()),
        "per_blocks": {b: {"variants": v[0], "hypotheses_each": v[1]} for b, v in per.items()},
    }, True


def _print_assignment_count(res: dict[str, Any]) -> None:
    print(
        f"Q = {res['q']} objects, N = {res['n']} measurements: {_big(res['variants'])} "
        f"unresolved variants, {_big(res['total'])} hypotheses"
    )
    for b, v in res["per_blocks"].items():
        print(
            f"  {b} blocks: {_big(v['variants'])} variants × {_big(v['hypotheses_each'])} "
            "hypotheses"
        )


def run_demo(out: Path, args: argparse.Namespace, progress: bool) -> dict[str, Any]:
    """``optmodels demo``: the closely spaced space objects of paper 004 in
    ``out/assignment``."""
    from optmodels.demo import run_assignment_demo

    return run_assignment_demo(out / "assignment", seed=args.seed, progress=progress)


def run_details(
    out: Path, *, sizes: list[int], runs: int, repeats: int, seed: int, progress: bool
) -> tuple[str, dict[str, Any]]:
    """``optmodels compare --details``: :mod:`solvers_cmp.assignment`'s rows; the report
    section and the result entry."""
    from solvers_cmp import assignment as cmp_as

    rows = cmp_as.rows(seed=seed, repeats=max(1, min(repeats, 3)), progress=progress)
    md = cmp_as.write_report(out, rows)
    return md, {"results": rows}


def register(sub: Any) -> None:
    """Add ``optmodels assignment solve`` and ``count`` to the top-level sub-commands
    ``sub``."""
    positive, count0, count1 = _positive(), _count(0), _count(1)
    asub = _group(sub, "assignment", "joint assignment with merges (paper 004)")
    aso = _leaf(asub, "solve", "the MAP hypothesis of a CASE.json")
    aso.add_argument(
        "case",
        help="JSON with means, covs, measurements, meas_cov (one d×d or "
        "a list of N), volume, pd, and rho or a sensor block "
        "({range: m, azimuth_deg: deg, site: [x, y]} or "
        "{ellipse: [[m²]]}, weights) [, max_group_size, "
        "group_gate]",
    )
    aso.add_argument(
        "--method",
        choices=("milp", "brute-force", "linear"),
        default="milp",
        help="one MILP, enumeration (13)-(14), or the linear assignment without merges",
    )
    aso.add_argument("--solver", default="HIGHS", help="MILP solver (HIGHS, SCIP, ...)")
    aso.add_argument("--time-limit", type=positive, help="MILP time limit, s (> 0)")
    aso.add_argument("--k", type=count0, default=0, help="also list the k best and marginals")
    aso.set_defaults(func=_assignment_solve, printer=_print_assignment_solve)
    aco = _leaf(asub, "count", "number of hypotheses (14) for Q objects, N marks")
    aco.add_argument("q", type=count1, help="objects Q (>= 1)")
    aco.add_argument("n", type=count0, help="measurements N (>= 0)")
    aco.set_defaults(func=_assignment_count, printer=_print_assignment_count)
