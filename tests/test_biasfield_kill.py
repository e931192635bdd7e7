"""Writes that survive a kill (issue 28, item 2) for the bias-field writers: ``build
--out``, ``solve``'s field.npz / field.csv, ``correct --out`` and ``FieldMap.save``. Each
writer is killed (SIGKILL) at seeded random moments of its run; the file written before
must still be readable and whole. Ctrl-C of ``build`` / ``correct`` exits 130 and says what
was and was not written."""

from __future__ import annotations

import csv
import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.test_cli import OPTMODELS, run_cli

TRIALS = 3


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    from optmodels.scenarios.recording import simulate_recording

    tmp = tmp_path_factory.mktemp("kill")
    sim = simulate_recording(tmp / "sim", seed=5, aircraft=8, duration=600.0, adsb_interval=4)
    run_cli(
        "biasfield",
        "build",
        sim.recording,
        "--radars",
        sim.sites,
        "--cells",
        "25",
        "--out",
        tmp / "fd.npz",
    )
    run_cli(
        "biasfield", "solve", tmp / "fd.npz", "--method", "closed-form", "--out", tmp / "solved"
    )
    run_cli(
        "biasfield",
        "correct",
        sim.recording,
        "--radars",
        sim.sites,
        "--field",
        tmp / "solved" / "field.npz",
        "--out",
        tmp / "corrected.csv",
    )
    return {"tmp": tmp, "rec": sim.recording, "sites": sim.sites}


def _env() -> dict[str, str]:
    return {**os.environ, "MPLBACKEND": "Agg", "PYTHONWARNINGS": "ignore"}


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _npz_whole(p: Path) -> None:
    with np.load(p, allow_pickle=False) as z:
        for k in z.files:
            z[k]  # every member decompresses (CRC checked)


def _csv_rows(p: Path) -> int:
    with p.open(encoding="utf-8") as fh:
        return len(list(csv.DictReader(fh)))


def _timed(argv: list[str]) -> float:
    t = time.perf_counter()
    proc = subprocess.run(
        [str(OPTMODELS), *argv], capture_output=True, env=_env(), check=False, timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    return time.perf_counter() - t


def _kill_trials(argv: list[str], targets: dict[Path, object], seed: int) -> list[int]:
    """Run ``argv`` ``TRIALS`` times, each SIGKILLed after a seeded uniform delay over
    (0.3, 1.1) × its measured run time; after each kill every target is byte-identical to
    what it was (the runs rewrite the same content, so a whole new file is the same) and
    readable by its checker. Returns the exit codes (−9 killed, 0 finished first)."""
    before = {p: _digest(p) for p in targets}
    span = _timed(argv)
    rng = np.random.default_rng(seed)
    codes = []
    for _ in range(TRIALS):
        proc = subprocess.Popen(
            [str(OPTMODELS), *argv],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=_env(),
        )
        time.sleep(float(rng.uniform(0.3, 1.1)) * span)
        proc.send_signal(signal.SIGKILL)
        codes.append(proc.wait(timeout=60))
        for p, check in targets.items():
            assert _digest(p) == before[p], p
            check(p)  # type: ignore[operator]
    return codes


@pytest.mark.slow
def test_kill_build_leaves_the_previous_field_data(small: dict[str, Path]) -> None:
    tmp = small["tmp"]
    _kill_trials(
        [
            "biasfield",
            "build",
            str(small["rec"]),
            "--radars",
            str(small["sites"]),
            "--cells",
            "25",
            "--out",
            str(tmp / "fd.npz"),
        ],
        {tmp / "fd.npz": _npz_whole},
        seed=11,
    )


@pytest.mark.slow
def test_kill_solve_leaves_the_previous_field(small: dict[str, Path]) -> None:
    tmp = small["tmp"]
    n = _csv_rows(tmp / "solved" / "field.csv")
    _kill_trials(
        [
            "biasfield",
            "solve",
            str(tmp / "fd.npz"),
            "--method",
            "closed-form",
            "--out",
            str(tmp / "solved"),
        ],
        {
            tmp / "solved" / "field.npz": _npz_whole,
            tmp / "solved" / "field.csv": lambda p: _csv_rows(p) == n or 1 / 0,
        },
        seed=12,
    )


def test_kill_correct_leaves_the_previous_csv(small: dict[str, Path]) -> None:
    tmp = small["tmp"]
    n = _csv_rows(tmp / "corrected.csv")
    assert n > 500
    _kill_trials(
        [
            "biasfield",
            "correct",
            str(small["rec"]),
            "--radars",
            str(small["sites"]),
            "--field",
            str(tmp / "solved" / "field.npz"),
            "--out",
            str(tmp / "corrected.csv"),
        ],
        {tmp / "corrected.csv": lambda p: _csv_rows(p) == n or 1 / 0},
        seed=13,
    )


def test_kill_fieldmap_save_in_a_loop(small: dict[str, Path], tmp_path: Path) -> None:
    """A process saving a FieldMap onto the same file over and over, killed at seeded
    random moments: the file always loads (every kill falls inside some write or between
    two; a non-atomic np.savez_compressed leaves a truncated archive)."""
    from optmodels.biasfield.usage import FieldMap

    src = small["tmp"] / "solved" / "field.npz"
    target = tmp_path / "map.npz"
    FieldMap.load(src).save(target)
    code = (
        "import sys\nfrom optmodels.biasfield.usage import FieldMap\n"
        f"fm = FieldMap.load({str(src)!r})\nprint('ready', flush=True)\n"
        f"while True:\n    fm.save({str(target)!r})\n"
    )
    rng = np.random.default_rng(14)
    for _ in range(TRIALS + 2):
        proc = subprocess.Popen(
            [sys.executable, "-c", code],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            env=_env(),
            text=True,
        )
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        time.sleep(float(rng.uniform(0.05, 0.5)))
        proc.kill()
        proc.wait(timeout=60)
        fm = FieldMap.load(target)
        assert fm.field.shape == FieldMap.load(src).field.shape


@pytest.mark.slow
@pytest.mark.parametrize("verb", ["build", "correct"])
def test_ctrl_c_says_what_was_and_was_not_written(small: dict[str, Path], verb: str) -> None:
    """SIGINT part-way: exit 130, one line naming the output not written and that the
    previous one is unchanged; the previous file is byte-identical."""
    tmp = small["tmp"]
    if verb == "build":
        out = tmp / "fd.npz"
        argv = [
            "biasfield",
            "build",
            str(small["rec"]),
            "--radars",
            str(small["sites"]),
            "--cells",
            "25",
            "--out",
            str(out),
        ]
    else:
        out = tmp / "corrected.csv"
        argv = [
            "biasfield",
            "correct",
            str(small["rec"]),
            "--radars",
            str(small["sites"]),
            "--field",
            str(tmp / "solved" / "field.npz"),
            "--out",
            str(out),
        ]
    before = _digest(out)
    span = _timed(argv)
    for frac in (0.7, 0.55, 0.85, 0.4, 0.95):  # past the interpreter's start into the work
        proc = subprocess.Popen(
            [str(OPTMODELS), *argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=_env(),
            text=True,
        )
        time.sleep(frac * span)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
        if proc.returncode in (0, -signal.SIGINT):
            # finished before the signal, or still importing the command line itself
            # (Python's own KeyboardInterrupt before optmodels runs): another moment
            assert _digest(out) == before
            continue
        assert proc.returncode == 130, err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert len(lines) == 1 and "interrupted while" in lines[0], err
        assert f"{out} not written" in lines[0] and "unchanged" in lines[0]
        assert _digest(out) == before
        return
    pytest.fail(f"{verb} finished before every SIGINT (run time {span:.1f} s)")
