"""optmodels.montecarlo: engines give identical results, checkpoints resume after a kill,
built-in studies agree with their analytic values within Monte Carlo error."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from optmodels import montecarlo as mc
from optmodels import trajectories as tr
from optmodels.core import ProblemError

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Slow:
    """A study whose trials take ``pause`` seconds (to be killed midway)."""

    pause: float = 0.02

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        time.sleep(self.pause)
        x = rng.normal(size=3)
        return {"a": float(x[0]), "b": float(x @ x)}


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
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        by_address = mc.run(Slow(0.0), 50, seed=2, scheduler=cluster.scheduler_address,
                            chunk=6)
        with distributed.Client(cluster) as client:
            by_client = mc.run(Slow(0.0), 50, seed=2, scheduler=client, chunk=11)
    local = mc.run(Slow(0.0), 50, seed=2, scheduler="serial")
    _same(local, by_address)
    _same(local, by_client)
    assert by_address.engine.startswith("dask")


def test_checkpoint_resumes_after_kill(tmp_path: Path) -> None:
    ckpt = tmp_path / "study.jsonl"
    code = ("from optmodels import montecarlo as mc\n"
            "from tests.test_montecarlo import Slow\n"
            f"mc.run(Slow(0.01), 300, seed=9, scheduler='serial', chunk=5, "
            f"checkpoint={str(ckpt)!r})\n")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
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


@pytest.mark.parametrize("kwargs, match", [
    ({"trials": 0}, "trials"), ({"trials": 2.5}, "trials"), ({"seed": -1}, "seed"),
    ({"scheduler": "threads"}, "scheduler"), ({"workers": 0}, "workers"),
    ({"chunk": 0}, "chunk"),
])
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
    far = mc.run("assignment-separation", 300, seed=1, scheduler="serial",
                 params={"separation": 6.0})
    near = mc.run("assignment-separation", 300, seed=1, scheduler="serial",
                  params={"separation": 0.5})
    assert far.summary["rate"] >= 0.95
    assert far.summary["rate"] - near.summary["rate"] > 4 * np.hypot(far.summary["se"],
                                                                    near.summary["se"])
