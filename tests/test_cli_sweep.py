"""Subprocess sweep over every CLI verb and flag (issue 28 item 5): the exit-code contract.

The verbs and their flags are **walked from the argparse parsers**
(:func:`optmodels.cli.build_parser`), not listed by hand. Every run goes through the
installed console script (:data:`tests.test_cli.OPTMODELS`) and must keep the contract of
README "Command line": exit 0 (solved), 1 (solved, not OK) or 2 (bad input), never a
traceback; with ``--json`` exactly one strict JSON document on stdout; a refusal is one
line on stderr (``optmodels: error: ...``) and, with ``--json``, the error document.

* every verb with no arguments (a missing input) and with ``--help``;
* every verb on small good inputs (the verbs that need a recording, a study or a demo get a
  damaged input: a refusal, fast);
* sampled (verb, flag, value) cases: each flag with an empty, non-numeric, NaN, negative,
  huge or unknown value, or a store-true flag added. CI draws :data:`N_CI` of them;
  ``OPTMODELS_SWEEP=full`` or the ``slow`` test (``make test-all``) runs every one.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from optmodels.cli import build_parser
from tests.test_cli import CliRun, run_cli, run_many

FULL = os.environ.get("OPTMODELS_SWEEP", "") == "full"
N_CI = 4

#: verbs whose good run is long (a demo, a comparison, a study): only refusals are run
HEAVY = {("demo",), ("compare",), ("montecarlo",)}
#: values tried for a flag that takes one
VALUES = ["", "x", "nan", "-1", "0", "1e999", "inf", "[[1, 2], [3]]", "/proc/optmodels-x"]


def walk(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """verb path -> its parser, for every leaf of the command tree."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return {path: parser}
    out: dict[tuple[str, ...], argparse.ArgumentParser] = {}
    for action in subs:
        for name, sub in action.choices.items():
            out.update(walk(sub, (*path, name)))
    return out


VERBS = walk(build_parser())


def flags(verb: tuple[str, ...]) -> list[argparse.Action]:
    return [
        a
        for a in VERBS[verb]._actions
        if a.option_strings
        and not isinstance(a, argparse._HelpAction | argparse._VersionAction)
        and a.dest not in ("json", "debug")
    ]


def check_contract(run: CliRun) -> None:
    """Exit 0/1/2, no traceback (run_cli checks), one JSON document with --json, and a
    refusal on one stderr line (with the error document)."""
    assert run.code in (0, 1, 2), f"{run.argv}: exit {run.code}\n{run.err[-2000:]}"
    if "--json" in run.argv and "--help" not in run.argv:
        doc = run.json()
        if run.code == 2:
            assert isinstance(doc, dict) and doc.get("exit_code") == 2, (run.argv, doc)
    if run.code == 2:
        lines = run.err_lines
        assert len(lines) == 1 and lines[0].startswith("optmodels: error: "), (run.argv, lines)


# ------------------------------------------------------------------ inputs
@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cli_sweep")
    rng = np.random.default_rng(28)
    ang = np.linspace(0, 3, 40)
    pts = np.c_[np.cos(ang), np.sin(ang), np.zeros(40)] * 5e3 + rng.normal(scale=5, size=(40, 3))
    (d / "plane.csv").write_text(
        "t,x,y,z\n"
        + "".join(f"{i},{a:.17g},{b:.17g},{c:.17g}\n" for i, (a, b, c) in enumerate(pts))
    )
    (d / "traj.csv").write_text(
        "object,t,y\n"
        + "".join(
            f"{j},{t},{2.0 * t + j + rng.normal():.17g}\n" for j in range(2) for t in range(8)
        )
    )
    (d / "case.json").write_text(
        json.dumps(
            {
                "means": [[0, 0], [10, 0]],
                "covs": [np.eye(2).tolist()] * 2,
                "measurements": [[0.1, -0.2], [9.8, 0.3], [5, 5]],
                "meas_cov": np.eye(2).tolist(),
                "volume": 400.0,
                "pd": 0.9,
                "rho": 0.2,
            }
        )
    )
    (d / "damaged.bin").write_bytes(b"\x30\x00\x05garbage")
    return {
        "plane": d / "plane.csv",
        "traj": d / "traj.csv",
        "case": d / "case.json",
        "damaged": d / "damaged.bin",
        "dir": d,
    }


def base(verb: tuple[str, ...], f: dict[str, Path]) -> list[str]:
    """A small good command line of ``verb`` (a damaged input for the verbs that need a
    recording or a long run)."""
    good: dict[tuple[str, ...], list[Any]] = {
        ("plane", "fit"): [f["plane"], "--sigma2", "25"],
        ("plane", "track"): [f["plane"], "--sigma2", "25", "--window", "growing"],
        ("trajectories", "fit"): [f["traj"]],
        ("assignment", "solve"): [f["case"]],
        ("assignment", "count"): ["2", "3"],
        ("fusion", "weights"): [
            "--s1",
            "[[2, 0.3], [0.3, 1]]",
            "--s2",
            "[[1, 0], [0, 3]]",
            "--n",
            "30",
        ],
        ("montecarlo",): ["no-such-study", "--trials", "2"],
        ("demo",): ["no-such-problem"],
        ("compare",): ["--problems", "no-such-problem"],
    }
    rest = good.get(verb)
    if rest is None:  # biasfield verbs: a damaged recording (refused before any work)
        rest = [f["damaged"]] + (
            ["--radars", f["damaged"]] if any(a.dest == "radars" for a in flags(verb)) else []
        )
    return [*verb, *map(str, rest)]


# ------------------------------------------------------------------ tests
def test_the_walk_finds_every_verb() -> None:
    """The parsers are walked (every problem's verbs and the faces), not listed."""
    from optmodels import registry

    problems = {v[0] for v in VERBS}
    assert set(registry.names()) <= problems | {"biasfield"}, problems
    assert {("demo",), ("compare",), ("montecarlo",)} <= set(VERBS)
    assert all(len(flags(v)) >= 0 for v in VERBS)


def test_every_verb_without_arguments_and_with_help(tmp_path: Path) -> None:
    """``--help`` of every verb; every verb without arguments (not the faces whose
    defaults are a whole demo, comparison or study run)."""
    runs = run_many(
        [[*v, "--json"] for v in sorted(VERBS) if v not in HEAVY]
        + [[*v, "--help"] for v in sorted(VERBS)],
        expect=None,
        cwd=tmp_path,
    )
    for run in runs:
        check_contract(run)
        if "--help" in run.argv:
            assert run.code == 0 and "usage:" in run.out, run.argv
    required = [r for r in runs if "--json" in r.argv]
    # a verb with a required input refuses its absence with exit 2
    for run in required:
        verb = tuple(a for a in run.argv if not a.startswith("--"))
        needs = any(
            a.required or (not a.option_strings and a.nargs not in ("?", "*"))
            for a in VERBS[verb]._actions
            if not isinstance(a, argparse._HelpAction)
        )
        if needs:
            assert run.code == 2, run.argv


def test_every_verb_on_its_base_inputs(inputs: dict[str, Path]) -> None:
    runs = run_many(
        [[*base(v, inputs), "--json"] for v in sorted(VERBS)], expect=None, cwd=inputs["dir"]
    )
    for run in runs:
        check_contract(run)
    ok = {tuple(r.argv[:2]): r.code for r in runs}
    # the good inputs are solved (0 or 1), the damaged ones refused (2)
    for verb in [
        ("plane", "fit"),
        ("plane", "track"),
        ("trajectories", "fit"),
        ("assignment", "solve"),
        ("assignment", "count"),
        ("fusion", "weights"),
    ]:
        assert ok[verb] in (0, 1), (verb, ok[verb])


def _flag_cases() -> list[tuple[tuple[str, ...], str, str | None]]:
    out: list[tuple[tuple[str, ...], str, str | None]] = []
    for verb in sorted(VERBS):
        for action in flags(verb):
            flag = action.option_strings[-1]
            if action.nargs == 0:
                if verb not in HEAVY:
                    out.append((verb, flag, None))
                continue
            values = list(VALUES)
            if action.choices:
                values.append(str(next(iter(action.choices))))
            out += [(verb, flag, v) for v in values]
    return out


FLAG_CASES = _flag_cases()


def _run_flag_case(case: tuple[tuple[str, ...], str, str | None], f: dict[str, Path]) -> CliRun:
    verb, flag, value = case
    argv = base(verb, f)
    if verb in HEAVY and value is not None:
        argv = [*verb, flag, value, *argv[len(verb) :]]
    else:
        argv += [flag] if value is None else [flag, value]
    run = run_cli(*argv, "--json", expect=None, cwd=f["dir"], timeout=300)
    check_contract(run)
    if verb in HEAVY:
        assert run.code == 2, (run.argv, run.code)  # never the long run
    return run


@settings(
    max_examples=N_CI if not FULL else len(FLAG_CASES),
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(case=st.sampled_from(FLAG_CASES))
def test_sampled_flags_keep_the_exit_code_contract(inputs: dict[str, Path], case: Any) -> None:
    _run_flag_case(case, inputs)


@pytest.mark.slow
def test_every_flag_keeps_the_exit_code_contract(inputs: dict[str, Path]) -> None:
    """Every (verb, flag, value) case (``make test-all``); the counts go to the notes."""
    counts = {0: 0, 1: 0, 2: 0}
    for i in range(0, len(FLAG_CASES), 4):
        chunk = FLAG_CASES[i : i + 4]
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=4) as ex:
            for run in ex.map(lambda c: _run_flag_case(c, inputs), chunk):
                counts[run.code] += 1
    print(f"CLI sweep: {len(FLAG_CASES)} cases, exit codes {counts}")


# ------------------------------------------------------------ the small silent cases
def test_empty_origin_is_refused(inputs: dict[str, Path]) -> None:
    run = run_cli(
        "biasfield",
        "build",
        inputs["damaged"],
        "--radars",
        inputs["damaged"],
        "--origin",
        "",
        expect=None,
    )
    assert run.code == 2 and "--origin" in run.err, run.err


def test_duplicated_json_key_is_refused(inputs: dict[str, Path]) -> None:
    text = inputs["case"].read_text()
    dup = inputs["dir"] / "dup.json"
    dup.write_text(text.replace('"pd": 0.9', '"pd": 0.9, "pd": 0.1'))
    run = run_cli("assignment", "solve", dup, "--json", expect=None)
    check_contract(run)
    assert run.code == 2 and "twice" in run.err, run.err
