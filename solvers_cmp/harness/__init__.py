"""The comparison harness: cases × formulations × solvers × settings profile.

A *case* is (problem, instance, size, seed); a *run* is a case × formulation × solver ×
profile. Every run goes to a worker process (``isolate=True``, the default) with the
profile's time limit: a run that exceeds it, or crashes the interpreter (a solver
segfault), is recorded as a failed row (``time_limit`` / ``crashed``) and the worker is
restarted, so one bad run never stops a sweep. Rows are appended to ``results.csv`` as they
finish (whole lines, flush + fsync); a rerun skips rows already there (same problem,
instance, size, seed, formulation, solver, settings), so an interrupted sweep resumes where
it stopped.

Faults are handled as in :mod:`optmodels.montecarlo` (same helpers): the worker exits with
its parent, even after a SIGKILL, and ignores SIGINT; Ctrl-C kills the worker, keeps the
finished rows and raises :class:`optmodels.execution.Interrupted`; a second sweep on the
same folder gets a ``ProblemError`` (``results.csv.lock``); unreadable rows of
``results.csv`` (a last row cut short by a kill, garbage) are moved to
``results.csv.skipped``, logged, and run again.

The runs go through the execution engine,
:func:`optmodels.execution.execute`: here, in order, through the one local worker
(``scheduler=None``/``"processes"``; ``"serial"``: in this process), or on a Dask cluster (``scheduler="tcp://host:8786"``,
``optmodels compare --scheduler``): each run is then one Dask task, run in a child process
of its Dask worker with the same time limit
(:func:`~solvers_cmp.harness.remote._remote_run`), and a Dask worker that
dies records the run as ``crashed``. Only this process writes ``results.csv`` (rows in
the order they finish), so the rows, the resume, the lock and the repairs are those of
the local engine.

The worker builds each case's instance and its reference once (the closed form where the
paper has one, else the best known solution, see :mod:`solvers_cmp.cases`), then each run
is measured against it: ``solution_error`` (adapter-defined, relative), ``objective_gap``
(relative), ``max_violation`` (the package's NumPy re-check of the original problem), and
``success`` = status OK and error ≤ the profile's tolerance and violation ≤ tolerance
(qpbenchmark's definition), with ``reason`` saying why not.

Modules (their public names are importable from here; a private one only from its module):
:mod:`~solvers_cmp.harness.profiles` (:class:`Profile`, :data:`PROFILES`, ``_judge``),
:mod:`~solvers_cmp.harness.planning` (:class:`Case`, :func:`plan`, the argument checks),
:mod:`~solvers_cmp.harness.worker` (the isolated local :class:`Worker`, ``_InProcess``),
:mod:`~solvers_cmp.harness.remote` (the Dask path, ``_remote_run``),
:mod:`~solvers_cmp.harness.versions` (:func:`solver_version`),
:mod:`~solvers_cmp.harness.results` (:data:`COLUMNS`, ``results.csv`` lines,
:func:`read_results`), :mod:`~solvers_cmp.harness.sweep` (:func:`run_sweep`) and
:mod:`~solvers_cmp.harness.metrics` (:func:`shifted_geometric_mean`, :func:`summarise`).
"""

from optmodels.execution import CONNECT_TIMEOUT as CONNECT_TIMEOUT
from optmodels.execution import Interrupted as Interrupted
from optmodels.execution import LineLog as LineLog
from solvers_cmp.harness.metrics import shifted_geometric_mean, summarise
from solvers_cmp.harness.planning import Case, Sizes, plan
from solvers_cmp.harness.profiles import PROFILES, Profile
from solvers_cmp.harness.results import COLUMNS, KEY, read_results
from solvers_cmp.harness.sweep import run_sweep
from solvers_cmp.harness.versions import solver_version
from solvers_cmp.harness.worker import Worker

__all__ = [
    "COLUMNS",
    "KEY",
    "PROFILES",
    "Case",
    "Profile",
    "Sizes",
    "Worker",
    "plan",
    "read_results",
    "run_sweep",
    "shifted_geometric_mean",
    "solver_version",
    "summarise",
]
