"""The Dask path of the comparison harness: one run as one Dask task.

:func:`_remote_run` runs on a Dask worker, in a child :class:`~solvers_cmp.harness.worker.Worker`
(one per worker thread, kept in :data:`_REMOTE`) with the same time limit as the local
engine. Dask pickles it by reference (``solvers_cmp.harness.remote._remote_run``): the
package must be importable on the Dask workers.
"""

from __future__ import annotations

import threading
from typing import Any

from solvers_cmp import cases as cs
from solvers_cmp.common import cpu_name
from solvers_cmp.harness.planning import Case
from solvers_cmp.harness.versions import solver_version
from solvers_cmp.harness.worker import Worker, run_prepared

#: Per thread of a Dask worker: its isolated run process and the last case prepared.
_REMOTE = threading.local()


def _remote_run(
    ad_path: str, case: Case, run: cs.Run, options: dict[str, Any], limit: float, repeats: int = 1
) -> tuple[str, Any, float, str, str]:
    """One comparison run as a Dask task (``run_sweep(scheduler=ADDRESS)``): on the Dask
    worker, in a child process (one per worker thread, kept across tasks, restarted after
    a crash or a time-out) with the time limit enforced there, exactly as the local
    engine: the case's instance and reference first (``4 * limit``, once per case while
    the child lives; a failure is remembered for the case's other runs), then the run.
    Returns ``(kind, result, wall, solver_version, cpu)`` of this machine."""
    worker = getattr(_REMOTE, "worker", None)
    if worker is None:
        worker = _REMOTE.worker = Worker("-")
        _REMOTE.prepared = [None, None]
    return (
        *run_prepared(worker, _REMOTE.prepared, ad_path, case, run, options, limit, repeats),
        solver_version(run.solver),
        cpu_name(),
    )
