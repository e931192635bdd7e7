"""The command line as a contract (issue 14): stdout holds only the result (exactly one
JSON document with --json, even when a C library writes to fd 1), exit status 0 solved /
1 not OK / 2 bad input or usage / 3 internal error / 130 interrupted, and every error is
one line on stderr -- never a traceback. Malformed inputs run the installed console
script (helpers in test_cli.py); the fd-level and exit-path checks run main() in process.
"""

from __future__ import annotations

import ctypes
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from optmodels import cli
from optmodels.cli.problems import assignment as cli_assignment
from optmodels.core import SolveError
from optmodels.io import write_plane_csv
from tests.test_cli import assert_error, run_many


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Small valid and malformed inputs shared by the tests of this module."""
    from optmodels import biasfield as bf
    from optmodels.scenarios.radar_network import radar_network

    d = tmp_path_factory.mktemp("cli_contract")
    rng = np.random.default_rng(11)
    f: dict[str, Path] = {"dir": d / "adir", "file": d / "existing_file"}
    f["dir"].mkdir()
    f["file"].write_text("x")
    f["plane"] = d / "plane.csv"
    write_plane_csv(f["plane"], rng.normal(size=(12, 3)) * [100.0, 100.0, 1.0])
    f["traj"] = d / "traj.csv"
    f["traj"].write_text("object,t,y\na,0,1\na,1,2\na,2,3.1\nb,0,1\nb,1,2.2\nb,2,2.9\n")
    f["latin1"] = d / "latin1.csv"  # Windows-1252 "é" in a name column: not UTF-8
    f["latin1"].write_bytes(b"x,y,z\n1,2,3\n" + "é".encode("cp1252") + b",1,2\n")
    means = rng.uniform(0, 3, (3, 2))
    case = {
        "means": means.tolist(),
        "covs": [np.eye(2).tolist()] * 3,
        "measurements": (means + rng.normal(0, 0.5, (3, 2))).tolist(),
        "meas_cov": (0.25 * np.eye(2)).tolist(),
        "volume": 9.0,
        "pd": 0.9,
        "rho": 0.3,
    }
    f["case"] = d / "case.json"
    f["case"].write_text(json.dumps(case))
    for name, text in {
        "pd_high": json.dumps({**case, "pd": "high"}),
        "volume_null": json.dumps({**case, "volume": None}),
        "null": "null",
        "list": "[1, 2]",
        "ragged": json.dumps({**case, "means": [[1, 2], [3]]}),
        "truncated": json.dumps(case)[:40],
    }.items():
        f[name] = d / f"{name}.json"
        f[name].write_text(text)
    f["latin1_json"] = d / "latin1.json"
    f["latin1_json"].write_bytes(b'{"means": "\xe9"}')
    sc = radar_network(3, n_aircraft=30, duration=1200.0, fields="smooth")
    fd, _ = bf.build_field_data(sc.plots, sc.radars, cells=20)
    f["fd"] = d / "fd.npz"
    fd.save(f["fd"])
    f["not_npz"] = d / "bad.npz"
    f["not_npz"].write_text("not an npz")
    return f


# --------------------------------------------------------------- malformed input
def test_malformed_inputs_exit_2_with_one_line(files: dict[str, Path], tmp_path: Path) -> None:
    """The malformed inputs of issue 14 (and one per kind of flag check): exit 2, one
    line ``optmodels: error: ...`` naming the file or flag, no traceback, and with
    --json the error document as the only thing on stdout."""
    f = files
    cases: list[tuple[list[Any], tuple[str, ...]]] = [
        # files that cannot be read as what they should be
        (["plane", "fit", f["latin1"], "--sigma2", "1", "--json"], ("latin1.csv", "UTF-8")),
        (["trajectories", "fit", f["latin1"]], ("latin1.csv", "UTF-8")),
        (
            [
                "biasfield",
                "build",
                f["latin1"],
                "--radars",
                f["latin1"],
                "--out",
                tmp_path / "x.npz",
            ],
            ("latin1.csv", "UTF-8"),
        ),
        (["assignment", "solve", f["latin1_json"], "--json"], ("latin1.json", "UTF-8")),
        (["assignment", "solve", f["pd_high"], "--json"], ("pd",)),
        (["assignment", "solve", f["volume_null"]], ("volume",)),
        (["assignment", "solve", f["null"], "--json"], ("null.json", "JSON object")),
        (["assignment", "solve", f["list"]], ("list.json", "JSON object")),
        (["assignment", "solve", f["ragged"]], ("ragged.json",)),
        (["assignment", "solve", f["truncated"]], ("truncated.json", "JSON")),
        (["assignment", "solve", f["dir"]], ("adir",)),
        (["biasfield", "solve", f["not_npz"], "--out", tmp_path / "o1"], ("bad.npz",)),
        # output paths
        (["biasfield", "solve", f["fd"], "--out", f["file"], "--json"], ("--out",)),
        (
            [
                "montecarlo",
                "plane-angle",
                "--trials",
                "2",
                "--scheduler",
                "serial",
                "--out",
                f["file"] / "x.json",
            ],
            ("--out",),
        ),
        (
            [
                "montecarlo",
                "plane-angle",
                "--trials",
                "2",
                "--scheduler",
                "serial",
                "--checkpoint",
                f["dir"],
            ],
            ("--checkpoint", "adir"),
        ),
        # values the library refuses, and names the harness does not know
        (
            ["montecarlo", "plane-angle", "--trials", "2", "--param", "n=abc", "--json"],
            ("n", "abc"),
        ),
        (
            [
                "compare",
                "--problems",
                "fusion",
                "--solvers",
                "NOSUCH",
                "--out",
                tmp_path / "c1",
                "--json",
            ],
            ("--solvers", "NOSUCH"),
        ),
        (
            ["compare", "--problems", "fusion", "--instances", "bogus", "--out", tmp_path / "c2"],
            ("--instances", "bogus"),
        ),
        (
            [
                "biasfield",
                "solve",
                f["fd"],
                "--lipschitz",
                "--solver",
                "closed-form",
                "--out",
                tmp_path / "o2",
            ],
            ("--solver closed-form", "Lipschitz"),
        ),
        (["biasfield", "solve", f["fd"], "--box", "nan,1", "--out", tmp_path / "o3"], ("--box",)),
    ]
    runs = run_many([argv for argv, _ in cases], expect=None)
    for run, (_, fragments) in zip(runs, cases, strict=True):
        line = assert_error(run, 2, *fragments)
        assert "pip install" not in line, line


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["assignment", "count", "-1", "3", "--json"], ("argument q", "-1")),
        (["demo", "plane", "--runs", "-1", "--out", "{tmp}/d"], ("--runs", "-1")),
        (["compare", "--time-limit", "0", "--out", "{tmp}/c"], ("--time-limit",)),
        (["plane", "fit", "x.csv", "--sigma2", "nan"], ("--sigma2", "NaN")),
        (["plane", "fit", "x.csv", "--sigma2", "625", "--level", "1.5"], ("--level",)),
        (["trajectories", "fit", "x.csv", "--epoch", "inf"], ("--epoch", "inf")),
        (
            ["fusion", "weights", "--s1", "[[1]]", "--s2", "[[1]]", "--n", "2.5", "--json"],
            ("--n", "2.5"),
        ),
        (["compare", "--sizes", "10,0", "--out", "{tmp}/c"], ("--sizes",)),
        (["assignment", "solve", "case.json", "--time-limit", "-1"], ("--time-limit",)),
    ],
)
def test_flag_values_are_usage_errors(
    argv: list[str], fragments: tuple[str, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every numeric flag goes through an argparse type built on core.as_*: a bad value
    is a usage error before any work (in process: it never gets past the parser; the
    installed script runs the same main)."""
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    with pytest.raises(SystemExit) as info:
        cli.main(argv)
    assert info.value.code == 2
    cap = capsys.readouterr()
    lines = [x for x in cap.err.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("optmodels: error: "), lines
    assert all(f in lines[0] for f in fragments), lines[0]
    if "--json" in argv:
        assert json.loads(cap.out)["exit_code"] == 2
    else:
        assert cap.out == ""
    assert not any(tmp_path.iterdir())  # nothing written


# --------------------------------------------------------------- not OK: exit 1
def test_finished_but_not_ok_exits_1(files: dict[str, Path], tmp_path: Path) -> None:
    """A solve that finishes with a status that is not OK: exit 1, the result (with the
    status) still the one JSON document on stdout, one line on stderr saying why."""
    (lip,) = run_many(
        [
            [
                "biasfield",
                "solve",
                files["fd"],
                "--lipschitz",
                "--solver",
                "OSQP",
                "--out",
                tmp_path / "lip",
                "--json",
            ]
        ],
        expect=None,
    )
    assert lip.code == 1
    res = lip.json()
    assert res["status"] not in ("optimal", "optimal_inaccurate")
    assert res["objective"] is None or np.isfinite(res["objective"])  # strict JSON
    assert len(lip.err_lines) == 1 and lip.err_lines[0].startswith("optmodels: not OK")
    assert not (tmp_path / "lip" / "field.npz").exists()


def test_ok_runs_exit_0_and_agree_with_the_library(files: dict[str, Path], tmp_path: Path) -> None:
    """Exit 0 with the numbers of the library: a Monte Carlo study (same seeds -> the same
    trials, so the means agree to rounding, 1e-12 relative) written into a folder that
    does not exist yet, the MILP (its banner must not reach stdout) and a compare sweep
    whose closed-form references all succeed."""
    from optmodels import assignment as asg
    from optmodels import montecarlo as mc

    out = tmp_path / "new" / "deeper" / "mc.json"
    r_mc, r_asg, r_cmp = run_many(
        [
            [
                "montecarlo",
                "plane-angle",
                "--trials",
                "3",
                "--seed",
                "5",
                "--param",
                "n=20",
                "--scheduler",
                "serial",
                "--out",
                out,
                "--json",
            ],
            ["assignment", "solve", files["case"], "--json"],
            [
                "compare",
                "--problems",
                "fusion",
                "--instances",
                "independent",
                "--sizes",
                "3",
                "--solvers",
                "CLARABEL",
                "--out",
                tmp_path / "cmp",
                "--json",
            ],
        ],
        expect=0,
    )
    ref = mc.run(mc.study("plane-angle", n=20), 3, 5, scheduler="serial")
    res = r_mc.json()
    assert res["trials"] == 3
    for k in ref.values:
        assert res["means"][k] == pytest.approx(ref.mean(k), rel=1e-12, abs=1e-15)
    written = json.loads(out.read_text())
    np.testing.assert_allclose(written["values"]["ml"], ref.values["ml"], rtol=1e-12)
    sol = asg.solve(asg.AssignmentData(**json.loads(files["case"].read_text())))
    res = r_asg.json()
    assert res["status"] == "optimal"
    assert res["log_score"] == pytest.approx(sol.log_score, abs=1e-9)
    res = r_cmp.json()
    # 1 instance x 1 size x (closed form + CLARABEL on the weighted LSQ)
    assert res["runs"] == 2 and res["references_ok"] is True, res["failures"]


# ------------------------------------------------------------- in-process paths
def _patch_command(monkeypatch: pytest.MonkeyPatch, func: Any) -> None:
    """Make ``optmodels assignment count`` run ``func`` (the parser is built per call)."""
    monkeypatch.setattr(cli_assignment, "_assignment_count", func)


def test_c_level_stdout_goes_to_stderr(
    monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    """What a solver prints on fd 1 from C (HiGHS's banner, IPOPT's) -- here os.write and
    libc printf, whose buffer must be flushed before fd 1 is restored -- and Python
    prints during the work land on stderr; stdout is the one JSON document."""
    libc = ctypes.CDLL(None)

    def noisy(args: Any) -> tuple[dict[str, Any], bool]:
        os.write(1, b"banner via fd 1\n")
        libc.printf(b"banner via printf\n")
        print("python print during the work")
        return {"value": 1.5, "nan": float("nan"), "arr": np.arange(3)}, True

    _patch_command(monkeypatch, noisy)
    assert cli.main(["assignment", "count", "1", "0", "--json"]) == 0
    cap = capfd.readouterr()
    assert json.loads(cap.out) == {"value": 1.5, "nan": None, "arr": [0, 1, 2]}
    for text in ("banner via fd 1", "banner via printf", "python print during"):
        assert text in cap.err and text not in cap.out
    # the human output too: only the printer's text on stdout
    monkeypatch.setattr(cli_assignment, "_print_assignment_count", lambda res: print("RESULT"))
    assert cli.main(["assignment", "count", "1", "0"]) == 0
    cap = capfd.readouterr()
    assert cap.out == "RESULT\n" and "banner via printf" in cap.err


@pytest.mark.parametrize(
    ("exc", "code", "text"),
    [
        (ZeroDivisionError("float division by zero"), 3, "internal error: ZeroDivisionError"),
        (SolveError("the solver gave up"), 1, "not solved: the solver gave up"),
        (KeyboardInterrupt(), 130, "interrupted"),
        (OSError(28, "No space left on device"), 2, "No space left on device"),
    ],
)
def test_exit_paths_one_line(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    exc: BaseException,
    code: int,
    text: str,
) -> None:
    def boom(args: Any) -> tuple[dict[str, Any], bool]:
        raise exc

    _patch_command(monkeypatch, boom)
    assert cli.main(["assignment", "count", "1", "0", "--json"]) == code
    cap = capsys.readouterr()
    lines = [x for x in cap.err.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("optmodels: error: ") and text in lines[0]
    assert "Traceback" not in cap.err
    assert json.loads(cap.out) == {
        "error": lines[0].removeprefix("optmodels: error: "),
        "exit_code": code,
    }
    if code == 3:
        assert "--debug" in lines[0]
        assert cli.main(["assignment", "count", "1", "0", "--debug"]) == 3
        err = capsys.readouterr().err
        assert "Traceback" in err and "ZeroDivisionError" in err


def test_demo_part_failure_exits_1(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A multi-part command: a part that fails is reported, the others run, exit 1."""
    import optmodels.demo as demo

    def failing(out: Path, **kw: Any) -> dict[str, Any]:
        raise SolveError("IPOPT did not converge")

    monkeypatch.setattr(demo, "run_plane_demo", failing)
    assert cli.main(["demo", "plane", "--out", str(tmp_path), "--json"]) == 1
    res = json.loads(capsys.readouterr().out)
    assert res["failed"] == {"plane": "SolveError: IPOPT did not converge"}
    assert "FAILED" in (tmp_path / "index.md").read_text()


def test_usage_error_with_json_prints_the_error_document(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as info:
        cli.main(["plane", "fit", "x.csv", "--sigma2", "-1", "--json"])
    assert info.value.code == 2
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert doc["exit_code"] == 2 and "--sigma2" in doc["error"]
    lines = [x for x in cap.err.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("optmodels: error: ")


def test_ctrl_c_of_the_console_script_saves_and_resumes(tmp_path: Path) -> None:
    """SIGINT to the installed ``optmodels montecarlo`` (its whole process group, as a
    terminal's Ctrl-C): exit 130 within 2 s, one stderr line saying what was saved, no
    worker left; the rerun resumes from the checkpoint and its means equal an
    uninterrupted in-process run of the same study (trials are seeded per index, so
    bit-identical per trial; the means to 1e-12 relative for the summation order)."""
    import subprocess
    import time

    from optmodels import montecarlo as mc
    from tests.harness_adapters import children, interrupt, wait_gone
    from tests.test_cli import OPTMODELS, run_cli

    ckpt = tmp_path / "eta.jsonl"
    trials = ["--trials", "20000", "--seed", "5", "--param", "n=10"]
    argv = [
        str(OPTMODELS),
        "montecarlo",
        "trajectories-eta",
        *trials,
        "--workers",
        "2",
        "--checkpoint",
        str(ckpt),
        "--json",
    ]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.Popen(
        argv,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (
        not ckpt.exists() or len(ckpt.read_text().splitlines()) < 3
    ):
        time.sleep(0.05)
    assert len(ckpt.read_text().splitlines()) >= 3, "the study never checkpointed"
    workers = children(proc.pid)
    out, err, took = interrupt(proc)
    assert proc.returncode == 130 and took < 2.0, (proc.returncode, took, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "interrupted after" in lines[0], err
    assert "Traceback" not in err and json.loads(out)["exit_code"] == 130
    assert wait_gone(workers, 5.0) == [], "a worker outlived the interrupted study"
    done = len(ckpt.read_text().splitlines())
    assert done < 21, "the study finished before the interrupt: nothing was tested"
    again = json.loads(
        run_cli("montecarlo", "trajectories-eta", *trials, "--checkpoint", ckpt, "--json").out
    )
    assert 0 < again["resumed"] < 20000 and again["trials"] == 20000
    ref = mc.run(mc.study("trajectories-eta", n=10), 20000, 5, scheduler="serial")
    for k, v in again["means"].items():
        assert v == pytest.approx(ref.mean(k), rel=1e-12), k
