"""Where tasks run (base layer): serial, a local process pool or Dask distributed.

* :func:`as_scheduler` / :func:`scheduler_argument`: the one scheduler vocabulary
  (``"serial"``, ``"processes"``, a Dask address ``tcp://host:8786`` or a
  ``distributed.Client``) of every entry point and every CLI ``--scheduler`` flag;
* :func:`execute`: run tasks and hand their results back here as they finish (the
  process pool: :func:`run_pool`; Dask: :func:`dask_client`, which bounds the connection
  *and* the handshake by ``connect_timeout`` and refuses a peer that is not a Dask
  scheduler, :func:`probe_dask`);
* worker guards: :func:`guard_worker` (workers exit with their parent, even after a
  SIGKILL, and ignore SIGINT), :func:`sigint_ignored`, :func:`kill_pool`;
* :class:`LineLog`: locked, line-oriented files appended with fsync (the Monte Carlo
  checkpoints, the comparison's ``results.csv``), :func:`report_skipped`;
* :class:`Interrupted`: Ctrl-C after what had finished was saved.

This package imports only :mod:`optmodels.core` (and, lazily, ``distributed``).
"""

from optmodels.execution.engine import MAX_WORKERS, describe, execute, run_pool
from optmodels.execution.files import LineLog, log, report_skipped
from optmodels.execution.interrupt import Interrupted
from optmodels.execution.scheduler import (
    CONNECT_TIMEOUT,
    SCHEDULERS,
    as_scheduler,
    dask_client,
    probe_dask,
    scheduler_argument,
)
from optmodels.execution.workers import guard_worker, kill_pool, sigint_ignored

__all__ = [
    "CONNECT_TIMEOUT",
    "MAX_WORKERS",
    "SCHEDULERS",
    "Interrupted",
    "LineLog",
    "as_scheduler",
    "dask_client",
    "describe",
    "execute",
    "guard_worker",
    "kill_pool",
    "log",
    "probe_dask",
    "report_skipped",
    "run_pool",
    "scheduler_argument",
    "sigint_ignored",
]
