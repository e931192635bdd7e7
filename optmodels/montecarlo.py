"""Seeded Monte Carlo studies on local processes or a Dask cluster, with checkpoints.

A *study* is a picklable callable ``study(rng) -> dict[str, float]``: one trial, drawing
everything from the :class:`numpy.random.Generator` it is given. :func:`run` gives trial
``i`` the generator ``default_rng([seed, i])``, so a trial's result depends only on
``(seed, i)`` -- not on the engine, the number of workers, the chunking, or whether the
study was interrupted and resumed. That is what makes the engines interchangeable and the
checkpoints safe.

Engines (``scheduler``):

* ``None`` or ``"processes"`` (default): a local process pool (``concurrent.futures``,
  spawn start method, ``workers`` processes, all cores by default);
* ``"serial"``: in this process (debugging, tiny studies);
* ``"tcp://host:8786"`` (any Dask address, ``inproc://`` included), or a
  ``distributed.Client``: Dask distributed (``pip install 'optmodels[distributed]'``).
  The study and optmodels must be importable on the workers.

Checkpoint (``checkpoint=PATH``): JSON lines, a header naming the study and seed, then one
line per finished chunk of trials, appended and flushed as chunks finish. Rerunning with
the same path skips the finished trials; a header that does not match (another study or
seed) is refused rather than mixed in. A line cut short by a kill is ignored.

Built-in studies (:data:`STUDIES`): plane angle error vs the CRB, trajectories η vs Monte
Carlo, Cov(vec Ŵ) vs (10), bias-field recovery error, association rate vs separation.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels.core import ProblemError, SolverNotAvailable

__all__ = ["STUDIES", "AssignmentSeparation", "BiasfieldRecovery", "FusionWeight",
           "MonteCarloResult", "PlaneAngle", "TrajectoriesEta", "run", "study"]

Study = Callable[[np.random.Generator], Mapping[str, float]]


@dataclass
class MonteCarloResult:
    """Per-trial values (arrays ordered by trial index) and the study's summary."""

    study: str
    seed: int
    trials: np.ndarray
    values: dict[str, np.ndarray]
    summary: dict[str, Any] = field(default_factory=dict)
    resumed: int = 0
    engine: str = ""

    def mean(self, key: str) -> float:
        return float(np.mean(self.values[key]))

    def se(self, key: str) -> float:
        """Standard error of the mean of ``values[key]``."""
        v = self.values[key]
        return float(np.std(v, ddof=1) / np.sqrt(v.size))


def _describe(study: Any) -> str:
    if is_dataclass(study) and not isinstance(study, type):
        return f"{type(study).__name__}{json.dumps(asdict(study), sort_keys=True)}"
    return getattr(study, "__qualname__", type(study).__name__)


def _chunk_task(study: Study, seed: int, indices: list[int]) -> list[tuple[int, dict[str, float]]]:
    """Run trials ``indices`` of ``study``; each gets ``default_rng([seed, i])``."""
    out = []
    for i in indices:
        res = study(np.random.default_rng([seed, i]))
        out.append((i, {k: float(v) for k, v in res.items()}))
    return out


def _read_checkpoint(path: Path, header: dict[str, Any]) -> dict[int, dict[str, float]]:
    if not path.exists():
        return {}
    done: dict[int, dict[str, float]] = {}
    with path.open() as fh:
        lines = fh.read().splitlines()
    if not lines:
        return {}
    try:
        head = json.loads(lines[0])
    except json.JSONDecodeError:
        head = None
    if head != header:
        raise ProblemError(f"checkpoint: {path} belongs to another study or seed ({head}); "
                           f"expected {header}. Use another path or delete it.")
    for line in lines[1:]:
        try:
            chunk = json.loads(line)
        except json.JSONDecodeError:  # the last line of a killed run may be cut short
            continue
        for i, vals in chunk:
            done[int(i)] = vals
    return done


class _Checkpoint:
    def __init__(self, path: Path | None, header: dict[str, Any], fresh: bool) -> None:
        self.fh = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            if fresh:
                # a cut-short last line would glue onto the next record: start a new line
                self.fh = path.open("w")
                self.fh.write(json.dumps(header) + "\n")
            else:
                self.fh = path.open("a")
                self.fh.write("\n")
            self.fh.flush()

    def add(self, chunk: list[tuple[int, dict[str, float]]]) -> None:
        if self.fh is not None:
            self.fh.write(json.dumps(chunk) + "\n")
            self.fh.flush()
            os.fsync(self.fh.fileno())

    def close(self) -> None:
        if self.fh is not None:
            self.fh.close()


def _chunks(todo: list[int], size: int) -> list[list[int]]:
    return [todo[k:k + size] for k in range(0, len(todo), size)]


def _dask_client(scheduler: Any) -> Any:
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - the test extra installs it
        raise SolverNotAvailable("scheduler: Dask distributed is not installed; "
                                 "pip install 'optmodels[distributed]'") from exc
    if isinstance(scheduler, Client):
        return scheduler, False
    return Client(scheduler), True


def run(study: Study | str, trials: int, seed: int = 0, *, scheduler: Any = None,
        checkpoint: str | Path | None = None, workers: int | None = None,
        chunk: int | None = None, progress: bool = False,
        params: Mapping[str, Any] | None = None) -> MonteCarloResult:
    """Run ``trials`` seeded trials of ``study`` and summarise them.

    Parameters
    ----------
    study : callable or str
        ``study(rng) -> {name: value}``, picklable (a module-level function or a dataclass
        instance such as :class:`PlaneAngle`), or the name of a built-in study in
        :data:`STUDIES` (``params`` then go to its constructor).
    trials : int
        Number of trials (≥ 1).
    seed : int
        Trial ``i`` uses ``numpy.random.default_rng([seed, i])``.
    scheduler : None, "processes", "serial", Dask address or ``distributed.Client``
        The engine (module docstring).
    checkpoint : path, optional
        JSON-lines file; finished trials found there are not run again.
    workers : int, optional
        Local processes (default: all cores).
    chunk : int, optional
        Trials per task (default: about 8 tasks per worker, at most 1000 trials).
    progress : bool
        Show a progress bar (tqdm).

    Returns
    -------
    MonteCarloResult
        ``values[key][j]`` is trial ``trials[j]``'s value; ``summary`` the study's
        ``summarise(values)`` when it has one; ``resumed`` how many trials came from the
        checkpoint.
    """
    if isinstance(study, str):
        study = _builtin(study, params or {})
    elif params:
        raise ProblemError("params: only for a built-in study given by name")
    if not callable(study):
        raise ProblemError(f"study: expected a callable rng -> dict, got {type(study).__name__}")
    if isinstance(trials, bool) or not isinstance(trials, int | np.integer) or trials < 1:
        raise ProblemError(f"trials: expected a positive integer, got {trials!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ProblemError(f"seed: expected a non-negative integer, got {seed!r}")
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise ProblemError(f"workers: expected a positive integer, got {workers!r}")
    if chunk is not None and (not isinstance(chunk, int) or chunk < 1):
        raise ProblemError(f"chunk: expected a positive integer, got {chunk!r}")
    trials, seed = int(trials), int(seed)
    name = _describe(study)
    header = {"study": name, "seed": seed}
    path = Path(checkpoint) if checkpoint is not None else None
    done = _read_checkpoint(path, header) if path is not None else {}
    done = {i: v for i, v in done.items() if i < trials}
    resumed = len(done)
    todo = [i for i in range(trials) if i not in done]
    ckpt = _Checkpoint(path, header, fresh=path is not None and not path.exists())
    nworkers = workers or os.cpu_count() or 1
    size = chunk or max(1, min(1000, -(-len(todo) // (8 * nworkers)) if todo else 1))
    parts = _chunks(todo, size)
    bar = tqdm(total=trials, initial=resumed, desc=name[:40], disable=not progress)

    def collect(res: list[tuple[int, dict[str, float]]]) -> None:
        for i, vals in res:
            done[i] = vals
        ckpt.add(res)
        bar.update(len(res))

    engine = "serial"
    try:
        if scheduler == "serial" or (not parts):
            for p in parts:
                collect(_chunk_task(study, seed, p))
        elif scheduler is None or scheduler == "processes":
            engine = f"processes ({nworkers})"
            import multiprocessing as mp

            with ProcessPoolExecutor(nworkers, mp_context=mp.get_context("spawn")) as ex:
                pending = {ex.submit(_chunk_task, study, seed, p) for p in parts}
                while pending:
                    finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for f in finished:
                        collect(f.result())
        elif not isinstance(scheduler, str) and not hasattr(scheduler, "submit"):
            raise ProblemError(f"scheduler: expected None, 'processes', 'serial', a Dask "
                               f"address or a distributed.Client, got {scheduler!r}")
        elif isinstance(scheduler, str) and "://" not in scheduler:
            raise ProblemError(f"scheduler: expected None, 'processes', 'serial' or a Dask "
                               f"address like tcp://host:8786, got {scheduler!r}")
        else:
            from distributed import as_completed

            client, own = _dask_client(scheduler)
            engine = f"dask ({client.scheduler.address})"
            try:
                futs = client.map(_chunk_task, [study] * len(parts), [seed] * len(parts),
                                  parts, pure=False)
                for f in as_completed(futs):
                    collect(f.result())
            finally:
                if own:
                    client.close()
    finally:
        bar.close()
        ckpt.close()
    order = np.arange(trials)
    keys = list(done[0].keys()) if trials else []
    values = {k: np.array([done[i][k] for i in order]) for k in keys}
    summary = study.summarise(values) if hasattr(study, "summarise") else {}
    return MonteCarloResult(name, seed, order, values, summary, resumed, engine)


# ============================================================================ studies
@dataclass(frozen=True)
class PlaneAngle:
    """Plane of maneuver (paper 000): angle error (rad) of the ML plane and of the
    unweighted SVD plane, and the Cramér–Rao bound of the angle for the trial's truth.
    ``setting``: "two-source" (D_i = α_i² D, closed form) or "radar" (general D_i,
    reduced NLP)."""

    n: int = 50
    setting: str = "radar"

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import plane, scenarios

        sc = (scenarios.two_source_plane(self.n, rng) if self.setting == "two-source"
              else scenarios.radar_plane(self.n, rng, geometry="broadside"))
        data = plane.PlaneData(sc.points, sc.cov, sc.alpha2)
        ml = (plane.closed_form(data) if data.proportional
              else plane.solve(data, "reduced")).require_ok()
        crb = plane.cramer_rao_bound(plane.PlaneData(sc.truth, sc.cov, sc.alpha2),
                                     sc.normal, sc.offset)
        return {"ml": float(plane.angle_error(ml.normal, sc.normal)),
                "svd": float(plane.angle_error(plane.svd_fit(data).normal, sc.normal)),
                "crb2": float(crb.angle_rms ** 2)}

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        crb = float(np.sqrt(np.mean(v["crb2"])))
        return {"rmse_ml": float(np.sqrt(np.mean(v["ml"] ** 2))),
                "rmse_svd": float(np.sqrt(np.mean(v["svd"] ** 2))), "crb": crb,
                "ml_over_crb": float(np.sqrt(np.mean(v["ml"] ** 2))) / crb}


@dataclass(frozen=True)
class TrajectoriesEta:
    """Dependent linear trajectories (paper 002): squared errors of object 0's velocity
    (the unique parameter of a diverging family) from the dependent fit and from its own
    independent line; Q objects at t = 0..N−1, σ = 1. The ratio of the means is η."""

    q: int = 2
    n: int = 10

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import trajectories as tr

        t = np.arange(self.n, dtype=float)
        v = rng.uniform(-2, 2, self.q)
        vals = [5.0 + v[j] * t + rng.normal(0, 1, self.n) for j in range(self.q)]
        data = tr.TrajectoryData([t] * self.q, vals, 1.0)
        dep = tr.closed_form(data, "diverging")
        ind = tr.closed_form(data, "independent")
        return {"dep": float((dep.velocity[0] - v[0]) ** 2),
                "ind": float((ind.velocity[0] - v[0]) ** 2)}

    def summarise(self, v: Mapping[str, np.ndarray]) -> dict[str, float]:
        from optmodels import trajectories as tr

        return {"eta_mc": float(np.mean(v["dep"]) / np.mean(v["ind"])),
                "eta_formula": tr.eta(self.n, self.q)}


@dataclass(frozen=True)
class FusionWeight:
    """Fusion (paper 003): Ŵ from n snapshots of two independent estimators (sample
    covariances about the sample mean), vec Ŵ per trial; the summary compares its sample
    covariance with the linearised (10)."""

    n: int = 30
    s1: tuple[tuple[float, ...], ...] = ((1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, 3.0))
    s2: tuple[tuple[float, ...], ...] = ((2.0, 0.5, 0.0), (0.5, 1.0, 0.2), (0.0, 0.2, 1.5))

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import fusion as fu

        s1, s2 = np.array(self.s1), np.array(self.s2)
        m = s1.shape[0]
        a1 = rng.multivariate_normal(np.zeros(m), s1, self.n)
        a2 = rng.multivariate_normal(np.zeros(m), s2, self.n)
        w = fu.weight_from_samples(a1, a2).ravel(order="F")
        return {f"w{k}": float(x) for k, x in enumerate(w)}

    def summarise(self, v: Mapping[str, np.ndarray]) -> dict[str, float]:
        from optmodels import fusion as fu

        s1, s2 = np.array(self.s1), np.array(self.s2)
        w = np.column_stack([v[f"w{k}"] for k in range(s1.size)])
        emp = np.diag(np.cov(w, rowvar=False))
        lin = np.diag(fu.weight_covariance(s1, s2, self.n, self.n, mean="sample"))
        return {"max_rel_diff_diag": float(np.max(np.abs(emp - lin) / lin)),
                "var_mc_mean": float(np.mean(emp)), "var_linear_mean": float(np.mean(lin))}


@dataclass(frozen=True)
class BiasfieldRecovery:
    """Bias field (paper 001): RMS error of the closed-form smoothest field (11) against
    the true smooth field, range (m) and azimuth (mrad), on synthetic uncertainty sets with
    ``noise`` metres of position noise."""

    cells: int = 200
    noise: float = 20.0

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import biasfield as bf

        data, truth = bf.synthetic_field_data(rng, cells=self.cells, noise=self.noise)
        f = bf.closed_form(data).require_ok().field
        err = f - truth
        return {"range_rms_m": float(np.sqrt(np.mean(err[..., 0] ** 2))),
                "azimuth_rms_mrad": float(np.sqrt(np.mean(err[..., 1] ** 2)) * 1e3)}


@dataclass(frozen=True)
class AssignmentSeparation:
    """Assignment (paper 004): two objects ``separation`` measurement-σ apart; below
    ``resolution`` σ the sensor returns one merged mark at the centroid, else one each
    (detection probability 1, no clutter in the truth, ρ = 0.05 in the model). A trial
    scores 1 when the MAP hypothesis gets the resolution right (merged vs not) and
    pairs every mark with its source."""

    separation: float = 1.0
    resolution: float = 1.5
    prior_sigma: float = 0.5

    def __call__(self, rng: np.random.Generator) -> dict[str, float]:
        from optmodels import assignment as asg

        truth = np.array([[0.0, 0.0], [self.separation, 0.0]])
        means = truth + rng.normal(0, self.prior_sigma, (2, 2))
        covs = np.stack([np.eye(2) * self.prior_sigma**2] * 2)
        merged = self.separation < self.resolution
        marks = (truth.mean(axis=0, keepdims=True) if merged else truth)
        meas = marks + rng.normal(0, 1.0, marks.shape)
        side = 20.0
        data = asg.AssignmentData(means, covs, meas, np.eye(2), side**2, 0.95, 0.05)
        sol = asg.solve(data).require_ok()
        blocks = [tuple(sorted(b)) for b in sol.partition]
        if merged:
            ok = blocks == [(0, 1)] and int(sol.assignment[0]) == 0
        else:
            ok = sorted(blocks) == [(0,), (1,)] and all(
                int(sol.assignment[k]) == b[0] for k, b in enumerate(sol.partition))
        return {"correct": float(ok)}

    @staticmethod
    def summarise(v: Mapping[str, np.ndarray]) -> dict[str, float]:
        p = float(np.mean(v["correct"]))
        return {"rate": p, "se": float(np.sqrt(p * (1 - p) / v["correct"].size))}


#: Built-in studies by name (the CLI's ``optmodels montecarlo NAME``).
STUDIES: dict[str, Callable[..., Study]] = {
    "plane-angle": PlaneAngle,
    "trajectories-eta": TrajectoriesEta,
    "fusion-weight": FusionWeight,
    "biasfield-recovery": BiasfieldRecovery,
    "assignment-separation": AssignmentSeparation,
}


def study(name: str, **params: Any) -> Study:
    """A built-in study by name, e.g. ``study("plane-angle", n=100)``."""
    return _builtin(name, params)


def _builtin(name: str, params: Mapping[str, Any]) -> Study:
    if name not in STUDIES:
        raise ProblemError(f"study: unknown study {name!r} (built-in: {sorted(STUDIES)})")
    return STUDIES[name](**params)

