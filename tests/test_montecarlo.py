"""optmodels.montecarlo: engines give identical results, checkpoints resume after a kill,
built-in studies agree with their analytic values within Monte Carlo error."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from optmodels import montecarlo as mc
from optmodels import trajectories as tr
from optmodels.core import ProblemError
from tests.harness_adapters import Flaky, Slow, children, interrupt, wait_gone

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def _failing(p: float, seed: int, n: int) -> set[int]:
    """The trials Flaky(p) fails, computed independently of the engine."""
    return {i for i in range(n) if np.random.default_rng([seed, i]).uniform() < p}


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines()) if path.exists() else 0


def _start(code: str) -> subprocess.Popen[str]:
    """A study in a child interpreter, in its own session (so that a signal can go to
    the whole process group, as a terminal's Ctrl-C does)."""
    return subprocess.Popen(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env=ENV,
        start_new_session=True,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_lines(proc: subprocess.Popen[str], path: Path, n: int, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while _lines(path) < n:
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(
                f"no {n} checkpoint lines (exit {proc.returncode}): {proc.communicate()[1][-2000:]}"
            )
        time.sleep(0.05)


def _same(r1: mc.MonteCarloResult, r2: mc.MonteCarloResult) -> None:
    assert r1.values.keys() == r2.values.keys()
    for k in r1.values:
        # bit-identical: trial i draws from default_rng([seed, i]) whatever the engine
        np.testing.assert_array_equal(r1.values[k], r2.values[k])


def test_serial_and_processes_identical() -> None:
    study = mc.TrajectoriesEta(q=3, n=8)
    serial = mc.run(study, 64, seed=5, scheduler="serial")
    procs = mc.run(study, 64, seed=5, scheduler="processes", workers=2, chunk=7)
    _same(serial, procs)
    assert procs.engine.startswith("processes")
    # and another seed gives other numbers (the seed is used)
    other = mc.run(study, 64, seed=6, scheduler="serial")
    assert not np.array_equal(other.values["dep"], serial.values["dep"])


def test_dask_local_cluster_identical() -> None:
    import distributed  # in the test extra (pyproject): must be here, never skipped

    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        by_address = mc.run(Slow(0.0), 50, seed=2, scheduler=cluster.scheduler_address, chunk=6)
        with distributed.Client(cluster) as client:
            by_client = mc.run(Slow(0.0), 50, seed=2, scheduler=client, chunk=11)
    local = mc.run(Slow(0.0), 50, seed=2, scheduler="serial")
    _same(local, by_address)
    _same(local, by_client)
    assert by_address.engine.startswith("dask")


def test_checkpoint_resumes_after_kill(tmp_path: Path) -> None:
    ckpt = tmp_path / "study.jsonl"
    code = (
        "from optmodels import montecarlo as mc\n"
        "from tests.harness_adapters import Slow\n"
        f"mc.run(Slow(0.01), 300, seed=9, scheduler='serial', chunk=5, "
        f"checkpoint={str(ckpt)!r})\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if ckpt.exists() and len(ckpt.read_text().splitlines()) >= 6:  # header + 5 chunks
                break
            time.sleep(0.05)
        else:
            pytest.fail("the study wrote no checkpoint lines within 120 s")
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL  # it really was killed midway
    resumed = mc.run(Slow(0.01), 300, seed=9, scheduler="serial", chunk=5, checkpoint=ckpt)
    assert 25 <= resumed.resumed < 300  # at least the 5 chunks seen, not the whole study
    _same(resumed, mc.run(Slow(0.0), 300, seed=9, scheduler="serial"))
    # a second rerun has nothing left to do
    again = mc.run(Slow(0.01), 300, seed=9, scheduler="serial", checkpoint=ckpt)
    assert again.resumed == 300


def test_checkpoint_refuses_another_study(tmp_path: Path) -> None:
    ckpt = tmp_path / "c.jsonl"
    mc.run(Slow(0.0), 10, seed=1, scheduler="serial", checkpoint=ckpt)
    with pytest.raises(ProblemError, match="checkpoint"):
        mc.run(Slow(0.0), 10, seed=2, scheduler="serial", checkpoint=ckpt)
    with pytest.raises(ProblemError, match="checkpoint"):
        mc.run(mc.TrajectoriesEta(), 10, seed=1, scheduler="serial", checkpoint=ckpt)


def test_cut_short_checkpoint_line_is_ignored(tmp_path: Path) -> None:
    ckpt = tmp_path / "c.jsonl"
    mc.run(Slow(0.0), 20, seed=1, scheduler="serial", checkpoint=ckpt, chunk=5)
    with ckpt.open("a") as fh:
        fh.write('[[20, {"a": 1.0')  # a kill in the middle of a write
    res = mc.run(Slow(0.0), 30, seed=1, scheduler="serial", checkpoint=ckpt, chunk=5)
    assert res.resumed == 20
    _same(res, mc.run(Slow(0.0), 30, seed=1, scheduler="serial"))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"trials": 0}, "trials"),
        ({"trials": 2.5}, "trials"),
        ({"seed": -1}, "seed"),
        ({"scheduler": "threads"}, "scheduler"),
        ({"workers": 0}, "workers"),
        ({"chunk": 0}, "chunk"),
    ],
)
def test_bad_arguments(kwargs: dict[str, object], match: str) -> None:
    args = {"trials": 4, "seed": 0, **kwargs}
    with pytest.raises(ProblemError, match=match):
        mc.run(Slow(0.0), args.pop("trials"), args.pop("seed"), **args)  # type: ignore[arg-type]


def test_unknown_study_and_params() -> None:
    with pytest.raises(ProblemError, match="study"):
        mc.run("no-such-study", 3)
    with pytest.raises(ProblemError, match="params"):
        mc.run(Slow(0.0), 3, params={"x": 1})


def test_trajectories_eta_matches_formula() -> None:
    # η = E(dep²)/E(ind²). Each mean of T = 6000 squared Gaussian errors has relative
    # standard error √(2/T) = 0.018; the two are positively correlated, so the ratio's
    # relative se is at most √2·0.018 = 0.026. Tolerance 4 se ≈ 0.10.
    res = mc.run("trajectories-eta", 6000, seed=3, scheduler="serial", params={"q": 2, "n": 10})
    assert res.summary["eta_formula"] == pytest.approx(tr.eta(10, 2))
    assert res.summary["eta_mc"] / res.summary["eta_formula"] == pytest.approx(1.0, abs=0.10)


def test_fusion_weight_matches_linearisation() -> None:
    # Var of each vec Ŵ entry from T = 3000 trials: relative se √(2/(T−1)) = 0.026 (4 se
    # = 0.10), plus the linearisation's own error at n = 30 (7 % measured with 10⁵ draws,
    # see test_fusion): tolerance 0.20.
    res = mc.run("fusion-weight", 3000, seed=4, scheduler="serial", params={"n": 30})
    assert res.summary["max_rel_diff_diag"] < 0.20


def test_assignment_rate_rises_with_separation() -> None:
    # 300 trials per point: se of a rate ≤ 0.029. Well resolved objects (6 σ apart) are
    # associated right nearly always; merged ones (0.5 σ) much less often.
    far = mc.run(
        "assignment-separation", 300, seed=1, scheduler="serial", params={"separation": 6.0}
    )
    near = mc.run(
        "assignment-separation", 300, seed=1, scheduler="serial", params={"separation": 0.5}
    )
    assert far.summary["rate"] >= 0.95
    assert far.summary["rate"] - near.summary["rate"] > 4 * np.hypot(
        far.summary["se"], near.summary["se"]
    )


# ------------------------------------------------------------------------ faults
def test_failing_trials_are_recorded_not_fatal(tmp_path: Path) -> None:
    ckpt = tmp_path / "f.jsonl"
    expected = _failing(0.05, 3, 400)
    assert 5 <= len(expected) <= 40  # ~20 of 400: the test exercises failures
    res = mc.run(
        Flaky(0.05), 400, seed=3, scheduler="processes", workers=2, chunk=9, checkpoint=ckpt
    )
    assert {i for i, _ in res.failures} == expected
    assert all(msg == "RuntimeError: trial exploded" for _, msg in res.failures)
    assert res.n_ok == 400 - len(expected) and res.requested == 400
    np.testing.assert_array_equal(res.trials, sorted(set(range(400)) - expected))
    # the values are those of the successful trials, bit-identical to a serial run, and
    # the summary is over them alone
    serial = mc.run(Flaky(0.05), 400, seed=3, scheduler="serial")
    _same(res, serial)
    assert res.summary["mean_b"] == pytest.approx(float(np.mean(serial.values["b"])), rel=1e-15)
    # a rerun takes successes and failures from the checkpoint and runs nothing
    again = mc.run(Flaky(0.05), 400, seed=3, scheduler="serial", checkpoint=ckpt)
    assert again.resumed == 400 and again.failures == res.failures
    lines = _lines(ckpt)
    # unless asked: the failed trials run again (and, being deterministic, fail again)
    retry = mc.run(Flaky(0.05), 400, seed=3, scheduler="serial", checkpoint=ckpt, retry_failed=True)
    assert retry.resumed == 400 - len(expected) and retry.failures == res.failures
    assert _lines(ckpt) > lines


def test_all_trials_failing_gives_an_empty_result() -> None:
    res = mc.run(Flaky(1.1), 5, seed=0, scheduler="serial")
    assert res.n_ok == 0 and len(res.failures) == 5 and res.summary == {}
    assert res.values == {} and res.trials.size == 0


def test_sigkill_of_the_parent_leaves_no_worker(tmp_path: Path) -> None:
    ckpt = tmp_path / "k.jsonl"
    code = (
        "from optmodels import montecarlo as mc\n"
        "from tests.harness_adapters import Slow\n"
        "if __name__ == '__main__':\n"
        f"    mc.run(Slow(0.01), 200, seed=4, workers=2, chunk=4, "
        f"checkpoint={str(ckpt)!r})\n"
    )
    proc = _start(code)
    _wait_lines(proc, ckpt, 4)  # header + 3 chunks: the pool is up and working
    kids = children(proc.pid)
    assert len(kids) >= 2  # the two workers (and multiprocessing's resource tracker)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(30)
    # PR_SET_PDEATHSIG kills the workers at once; the watchdog polls every 0.5 s
    assert wait_gone(kids, 10.0) == [], "workers outlived their SIGKILLed parent"
    resumed = mc.run(Slow(0.01), 200, seed=4, scheduler="serial", checkpoint=ckpt)
    assert 12 <= resumed.resumed < 200
    _same(resumed, mc.run(Slow(0.0), 200, seed=4, scheduler="serial"))


def test_ctrl_c_saves_and_exits_in_one_line(tmp_path: Path) -> None:
    ckpt = tmp_path / "i.jsonl"
    code = (
        "import sys\n"
        "from optmodels import montecarlo as mc\n"
        "from tests.harness_adapters import Slow\n"
        "if __name__ == '__main__':\n"
        "    try:\n"
        f"        mc.run(Slow(0.01), 200, seed=6, workers=2, chunk=4, "
        f"checkpoint={str(ckpt)!r})\n"
        "    except KeyboardInterrupt as exc:  # what the CLI does: one line, exit 130\n"
        "        print(f'optmodels: {exc}', file=sys.stderr)\n"
        "        sys.exit(130)\n"
    )
    proc = _start(code)
    _wait_lines(proc, ckpt, 4)
    kids = children(proc.pid)
    _, err, took = interrupt(proc)  # SIGINT to the whole group, as a terminal does
    assert proc.returncode == 130 and took < 2.0, (proc.returncode, took, err)
    assert len(err.splitlines()) == 1 and "interrupted after" in err, err
    assert wait_gone(kids, 5.0) == []
    finished = _lines(ckpt) - 1
    resumed = mc.run(Slow(0.01), 200, seed=6, scheduler="serial", checkpoint=ckpt)
    assert resumed.resumed == 4 * finished >= 12  # every chunk line written was kept
    _same(resumed, mc.run(Slow(0.0), 200, seed=6, scheduler="serial"))


class StopAfter:
    """Like ``Slow(0.0)``, but Ctrl-C (KeyboardInterrupt) at call ``limit + 1`` in this
    process (a class attribute: not part of the checkpoint header)."""

    limit: ClassVar[int] = 10
    calls: ClassVar[int] = 0

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        StopAfter.calls += 1
        if StopAfter.calls > StopAfter.limit:
            raise KeyboardInterrupt
        return Slow(0.0)(rng)


def test_interrupt_in_process_keeps_the_partial_result(tmp_path: Path) -> None:
    ckpt = tmp_path / "p.jsonl"
    StopAfter.calls, StopAfter.limit = 0, 12
    with pytest.raises(mc.Interrupted, match="interrupted after 10 of 20 trials") as info:
        mc.run(StopAfter(), 20, seed=1, scheduler="serial", checkpoint=ckpt, chunk=5)
    part = info.value.partial
    assert part.interrupted and part.n_ok == 10  # the two finished chunks
    _same(part, mc.run(Slow(0.0), 10, seed=1, scheduler="serial"))
    StopAfter.calls, StopAfter.limit = 0, 10**6
    res = mc.run(StopAfter(), 20, seed=1, scheduler="serial", checkpoint=ckpt, chunk=5)
    assert res.resumed == 10 and StopAfter.calls == 10
    _same(res, mc.run(Slow(0.0), 20, seed=1, scheduler="serial"))


def test_empty_and_cut_short_checkpoints_start_afresh(tmp_path: Path) -> None:
    ref = mc.run(Slow(0.0), 20, seed=1, scheduler="serial")
    empty = tmp_path / "empty.jsonl"
    empty.write_text("")  # a crash right after the file was created
    _same(mc.run(Slow(0.0), 20, seed=1, scheduler="serial", checkpoint=empty), ref)
    again = mc.run(Slow(0.0), 20, seed=1, scheduler="serial", checkpoint=empty)
    assert again.resumed == 20  # and the next run resumes from it
    head = tmp_path / "head.jsonl"
    head.write_text('{"study": "Sl')  # the header itself cut short
    assert mc.run(Slow(0.0), 20, seed=1, scheduler="serial", checkpoint=head).resumed == 0
    assert mc.run(Slow(0.0), 20, seed=1, scheduler="serial", checkpoint=head).resumed == 20


def test_garbage_checkpoint_lines_are_skipped_and_said(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    ckpt = tmp_path / "g.jsonl"
    mc.run(Slow(0.0), 20, seed=1, scheduler="serial", checkpoint=ckpt, chunk=5)
    with ckpt.open("ab") as fh:
        fh.write(b'{"x": 1}\n\xff\xfe garbage\n[[3, "no dict"]]\n[[21, {"a": 1.0')
    with caplog.at_level("WARNING", logger="optmodels"):
        res = mc.run(Slow(0.0), 30, seed=1, scheduler="serial", checkpoint=ckpt, chunk=5)
    assert res.skipped_lines == 4 and res.resumed == 20
    assert "skipped 3 unreadable lines and a last line cut short" in caplog.text
    _same(res, mc.run(Slow(0.0), 30, seed=1, scheduler="serial"))
    assert len((tmp_path / "g.jsonl.skipped").read_bytes().splitlines()) == 4
    clean = mc.run(Slow(0.0), 30, seed=1, scheduler="serial", checkpoint=ckpt)
    assert clean.skipped_lines == 0 and clean.resumed == 30


def test_foreign_file_is_refused_untouched(tmp_path: Path) -> None:
    for text in ("name,value\n1,2\n", "hello"):
        f = tmp_path / "notes.txt"
        f.write_text(text)
        with pytest.raises(ProblemError, match="not a Monte Carlo checkpoint"):
            mc.run(Slow(0.0), 5, seed=1, scheduler="serial", checkpoint=f)
        assert f.read_text() == text


def test_second_writer_is_refused_and_a_stale_lock_is_not(tmp_path: Path) -> None:
    ckpt = tmp_path / "w.jsonl"
    code = (
        "import time\n"
        "from optmodels.execution import LineLog\n"
        f"log = LineLog({str(ckpt)!r}, 'holder')\n"
        "print('locked', flush=True)\n"
        "time.sleep(60)\n"
    )
    holder = subprocess.Popen(
        [sys.executable, "-c", code], cwd=ROOT, env=ENV, stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        busy = re.escape(f"in use by another process (pid {holder.pid})")
        with pytest.raises(ProblemError, match=busy):
            mc.run(Slow(0.0), 5, seed=1, scheduler="serial", checkpoint=ckpt)
    finally:
        holder.kill()  # SIGKILL: the kernel releases its flock
        holder.wait(30)
    assert mc.run(Slow(0.0), 5, seed=1, scheduler="serial", checkpoint=ckpt).n_ok == 5


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"trials": float("nan")}, "trials"),
        ({"trials": True}, "trials"),
        ({"trials": 1e300}, "trials: must be <= 10000000"),  # the size guard, not a hang
        ({"workers": 10**6}, "workers: must be <= 256"),
        ({"checkpoint": "DIR"}, "is a directory"),
        ({"study": "plane-angle", "params": {"n": "abc"}}, "PlaneAngle n"),
        ({"study": "plane-angle", "params": {"setting": "sky"}}, "setting"),
        ({"study": "plane-angle", "params": {"zz": 1}}, "unknown parameter"),
        ({"study": "plane-angle", "params": [1]}, "params: expected a mapping"),
        ({"study": "fusion-weight", "params": {"n": 3}}, "FusionWeight n"),
        ({"study": "fusion-weight", "params": {"s1": [[1, 2], [2, 1]]}}, "s1"),
        ({"study": "assignment-separation", "params": {"prior_sigma": 0}}, "prior_sigma"),
        ({"scheduler": "tcp://"}, "scheduler"),
        ({"scheduler": 3}, "scheduler"),
    ],
)
def test_bad_arguments_more(tmp_path: Path, kwargs: dict[str, object], match: str) -> None:
    args: dict[str, object] = {"study": Slow(0.0), "trials": 4, "seed": 0, **kwargs}
    if args.get("checkpoint") == "DIR":
        args["checkpoint"] = tmp_path
    with pytest.raises(ProblemError, match=match):
        mc.run(
            args.pop("study"),
            args.pop("trials"),
            args.pop("seed"),  # type: ignore[arg-type]
            scheduler=args.pop("scheduler", "serial"),
            **args,
        )  # type: ignore[arg-type]


def test_unreachable_dask_scheduler_is_a_clear_error() -> None:
    t0 = time.monotonic()
    with pytest.raises(
        ProblemError,
        match=re.escape("cannot reach the Dask scheduler at tcp://127.0.0.1:9 within 1 s"),
    ):
        mc.run(Slow(0.0), 4, scheduler="tcp://127.0.0.1:9", connect_timeout=1.0)
    assert time.monotonic() - t0 < 15  # the connect timeout, not distributed's 30 s


# ------------------------------------------------------------ the shared engine: execute
def test_execute_serial_pool_and_a_lost_task() -> None:
    import math
    import operator

    from optmodels.execution import execute

    xs = np.random.default_rng(11).uniform(1.0, 100.0, size=6)
    tasks = [(math.sqrt, float(x)) for x in xs]
    got: dict[str, dict[int, float]] = {"serial": {}, "processes": {}}
    for engine in got:
        desc = execute(
            operator.call,
            tasks,
            scheduler=engine,
            workers=2,
            on_result=lambda k, v, e=engine: got[e].__setitem__(k, v),
        )
        assert desc.startswith(engine)
        assert sorted(got[engine]) == list(range(6))
        np.testing.assert_allclose([got[engine][k] for k in range(6)], np.sqrt(xs), rtol=1e-15)
    # a task that kills its worker is lost (with whatever was in flight with it), the
    # others still run in a new pool; each task is reported exactly once
    tasks.insert(2, (os._exit, 3))
    done: dict[int, float] = {}
    lost: list[int] = []
    execute(
        operator.call,
        tasks,
        scheduler="processes",
        workers=1,
        on_result=done.__setitem__,
        on_lost=lambda k, msg: lost.append(k),
    )
    assert 2 in lost and len(lost) <= 2 and not set(lost) & set(done)
    assert sorted([*lost, *done]) == list(range(7))
    want = dict(enumerate(np.sqrt(np.insert(xs, 2, np.nan))))
    for k, v in done.items():
        assert v == pytest.approx(want[k], rel=1e-15)
    with pytest.raises(ProblemError, match="compare scheduler"):
        execute(
            operator.call, tasks, scheduler="nowhere", on_result=done.__setitem__, what="compare"
        )
