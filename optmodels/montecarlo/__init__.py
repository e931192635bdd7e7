"""Seeded Monte Carlo studies on local processes or a Dask cluster, with checkpoints.

A *study* is a picklable callable ``study(rng) -> dict[str, float]``: one trial, drawing
everything from the :class:`numpy.random.Generator` it is given. :func:`run` gives trial
``i`` the generator ``default_rng([seed, i])``, so a trial's result depends only on
``(seed, i)`` -- not on the engine, the number of workers, the chunking, or whether the
study was interrupted and resumed. That is what makes the engines interchangeable and the
checkpoints safe.

Engines (``scheduler``, :func:`optmodels.execution.as_scheduler`; the engine itself is
:func:`optmodels.execution.execute`):

* ``None`` or ``"processes"`` (default): a local process pool (``concurrent.futures``,
  spawn start method, ``workers`` processes, all cores by default). Workers exit with
  their parent, even after a SIGKILL (Linux ``PR_SET_PDEATHSIG``, plus a watchdog thread
  polling ``os.getppid()`` every 0.5 s elsewhere), and ignore SIGINT (the parent handles
  Ctrl-C);
* ``"serial"``: in this process (debugging, tiny studies);
* ``"tcp://host:8786"`` (any Dask address, ``inproc://`` included), or a
  ``distributed.Client``: Dask distributed (``pip install 'optmodels[distributed]'``).
  The study and optmodels must be importable on the workers. An address that does not
  answer, or does not complete the Dask handshake, within ``connect_timeout`` (10 s), or
  a peer that is not a Dask scheduler, is a :class:`~optmodels.core.ProblemError`.

Faults:

* a trial that raises is a *failure*, recorded with its index and message
  (:attr:`MonteCarloResult.failures`, and in the checkpoint); the study goes on and the
  summary is computed over the successful trials (:attr:`MonteCarloResult.n_ok`). A rerun
  does not retry recorded failures unless ``retry_failed=True``. A worker process that
  dies (a trial crashed the interpreter) fails the chunks it had in flight; the pool is
  restarted for the rest;
* Ctrl-C (KeyboardInterrupt): the finished chunks are already in the checkpoint, the
  workers are killed, and :class:`Interrupted` (a ``KeyboardInterrupt``, one-line message,
  the partial result in ``.partial``) is raised; rerunning resumes;
* two processes on one checkpoint: the second gets a ``ProblemError`` (an ``fcntl.flock``
  on ``PATH.lock``, held for the run; the kernel drops it when the holder dies, so a
  killed run never blocks the next one).

Checkpoint (``checkpoint=PATH``): JSON lines, a header naming the study and seed, then one
line per finished chunk of trials (``[[i, {name: value}], ...]``) and one per chunk with
failures (``{"failed": [[i, message], ...]}``), appended as whole lines with flush + fsync.
Rerunning with the same path skips the recorded trials; a header that does not match
(another study or seed) or a file that is not a checkpoint is refused rather than mixed in
or overwritten. An empty file, or a header cut short by a crash, starts afresh; lines that
cannot be read (a last line cut short by a kill, garbage) are moved to ``PATH.skipped``,
logged (logger ``optmodels``) and counted (:attr:`MonteCarloResult.skipped_lines`).

Built-in studies (:data:`STUDIES`): plane angle error vs the CRB, trajectories η vs Monte
Carlo, Cov(vec Ŵ) vs (10), bias-field recovery error, association rate vs separation.
Their parameters are checked when the study is built (``ProblemError``).

Modules: :mod:`~optmodels.montecarlo.engine` (:func:`run`),
:mod:`~optmodels.montecarlo.studies` (the built-in studies, :func:`study`),
:mod:`~optmodels.montecarlo.results` (:class:`MonteCarloResult`) and
:mod:`~optmodels.montecarlo.checkpoint` (the checkpoint lines). The engine, the worker
guards, the locked line files and :class:`Interrupted` are in :mod:`optmodels.execution`
(``Interrupted`` is importable from here too).
"""

from optmodels.execution import Interrupted
from optmodels.montecarlo.engine import MAX_TRIALS as MAX_TRIALS
from optmodels.montecarlo.engine import run
from optmodels.montecarlo.results import MonteCarloResult
from optmodels.montecarlo.studies import (
    STUDIES,
    AssignmentSeparation,
    BiasfieldRecovery,
    FusionWeight,
    PlaneAngle,
    TrajectoriesEta,
    study,
)
from optmodels.montecarlo.studies import Study as Study

__all__ = [
    "STUDIES",
    "AssignmentSeparation",
    "BiasfieldRecovery",
    "FusionWeight",
    "Interrupted",
    "MonteCarloResult",
    "PlaneAngle",
    "TrajectoriesEta",
    "run",
    "study",
]
