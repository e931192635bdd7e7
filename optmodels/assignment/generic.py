r"""The generic solve of paper 004's joint assignment: the MAP hypothesis of (13)-(14) as
one exact MILP, decomposed into the connected components of the model's graph
(:mod:`~optmodels.assignment.decomposed`, direct HiGHS) or as one CVXPY model
(:mod:`~optmodels.assignment.milp`, the original form), ending in the NumPy re-check and
the gate :func:`optmodels.assignment.verify._finish`.

:func:`solve` reads validate (:func:`_check_args`, :func:`_decomposed_applies`) → build
(:func:`~optmodels.assignment.groups.candidate_groups`,
:func:`~optmodels.assignment.milp._columns`) → run and finish
(:func:`~optmodels.assignment.milp._solve_model` or
:func:`~optmodels.assignment.decomposed.solve_decomposed`, both ending in
:func:`~optmodels.assignment.verify._finish`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from optmodels.assignment.data import AssignmentData, Partition, _as_partition
from optmodels.assignment.decomposed import highspy_module, solve_decomposed
from optmodels.assignment.groups import candidate_groups
from optmodels.assignment.milp import _columns, _solve_model
from optmodels.assignment.solution import AssignmentSolution
from optmodels.backends.cvxpy_backend import as_milp_solver
from optmodels.core import (
    ProblemError,
    as_choice,
    as_flag,
    as_instance,
    as_number,
    as_positive,
    timed,
)


def solve(
    data: AssignmentData,
    *,
    solver: str = "HIGHS",
    mip_gap: float = 0.0,
    time_limit: float | None = None,
    fixed_partition: Partition | None = None,
    prune: bool = True,
    exclude: Sequence[AssignmentSolution] = (),
    model: str = "auto",
    **options: Any,
) -> AssignmentSolution:
    """The joint MAP hypothesis of (13)-(14) as one MILP (HiGHS by default): decomposed
    into the connected components of the model's graph (direct HiGHS,
    :mod:`~optmodels.assignment.decomposed`) or as one CVXPY model (the original form).

    Parameters
    ----------
    data : AssignmentData
    solver : str
        A CVXPY MILP solver (:data:`~optmodels.assignment.solvers.MILP_SOLVERS`; HIGHS,
        SCIPY, SCIP, ...). A continuous solver (CLARABEL, OSQP, ...) is refused with
        :class:`ProblemError`.
    mip_gap : float
        Relative MIP gap in [0, 1) to stop at; 0 (default) proves optimality. A solution
        with a reached gap above :data:`~optmodels.core.VERIFY_TOL` (relative to
        max(1, |score|)) is OPTIMAL_INACCURATE, never OPTIMAL.
    time_limit : float, optional
        Seconds, positive and finite (None: no limit). A solve stopped by it is
        ITERATION_LIMIT (with the gap reached in the message), never returned as a
        solution.
    fixed_partition : list of tuples, optional
        Solve one unresolved variant (the per-variant problem of (14)).
    prune : bool
        Exact dominance pruning (:mod:`~optmodels.assignment.milp`). ``False`` keeps every
        variable (needed when hypotheses other than the MAP matter, as in
        :func:`~optmodels.assignment.kbest.k_best`).
    exclude : sequence of AssignmentSolution
        Hypotheses to exclude, one sparse no-good cut each.
    model : {"auto", "decomposed", "cvxpy"}
        ``"decomposed"``: gated likelihoods, exact pruning, the exact split into
        connected components (closed forms for the uncontended ones, one direct HiGHS
        MILP for all contended ones; the same MAP). ``"cvxpy"``: the whole model in
        CVXPY (the original-form reference). ``"auto"`` (default) takes the decomposed
        path when it is exact and applies: solver HIGHS, no ``fixed_partition``,
        ``exclude`` or solver options other than ``verbose``, ``prune=True``, the default
        likelihood and prior.
    **options
        Passed to the solver (its own names; ``verbose=True`` shows its log).

    Returns
    -------
    AssignmentSolution
        The hypothesis, re-checked in NumPy
        (:func:`~optmodels.assignment.verify._recheck`): integrality, every constraint
        row, a valid partition and assignment, and the recomputed score (13) against the
        solver's objective; ``residuals`` holds them and the status is downgraded or
        refused by :func:`~optmodels.core.verified_status`.

    Raises
    ------
    ProblemError
        Bad arguments, or a model above the size guards
        :data:`~optmodels.assignment.groups.MAX_CANDIDATE_GROUPS`,
        :data:`~optmodels.assignment.milp.MAX_LIKELIHOOD_ENTRIES`,
        :data:`~optmodels.assignment.milp.MAX_MODEL_COLUMNS`,
        :data:`~optmodels.assignment.decomposed.MAX_MILP_COLUMNS` (checked before the
        model is allocated).
    """
    w = "assignment.solve"
    key, gap, limit, kind = _check_args(w, data, solver, mip_gap, time_limit, prune, exclude, model)
    direct_ok = _decomposed_applies(data, key, fixed_partition, exclude, prune, options)
    if kind == "decomposed" and not direct_ok:
        raise ProblemError(
            f"{w} model: 'decomposed' needs solver HIGHS, no "
            f"fixed_partition, exclude or solver options, prune=True and the "
            f"default likelihood and prior; use model='cvxpy'"
        )
    if kind != "cvxpy" and direct_ok:
        return solve_decomposed(
            data,
            candidate_groups(data),
            gap=gap,
            limit=limit,
            verbose=bool(options.get("verbose", False)),
            where=w,
        )
    fixed = None
    if fixed_partition is not None:
        fixed = _as_partition(f"{w} fixed_partition", fixed_partition, data.q)
        groups = sorted(set(fixed))
    else:
        groups = candidate_groups(data)
    with timed() as tb:
        groups, gain, keep = _columns(w, data, groups, fixed, prune)
    return _solve_model(
        w, data, groups, gain, keep, exclude, fixed, key, gap, limit, options, tb.elapsed
    )


def _check_args(
    w: str,
    data: Any,
    solver: Any,
    mip_gap: Any,
    time_limit: Any,
    prune: Any,
    exclude: Any,
    model: Any,
) -> tuple[str, float, float | None, str]:
    """The arguments of :func:`solve` checked (a ProblemError naming the one that is
    wrong): the MILP solver's key, the gap, the time limit (s) and the model kind."""
    as_instance(f"{w} data", data, AssignmentData)
    key = as_milp_solver(w, solver)
    gap = as_number(f"{w} mip_gap", mip_gap, low=0.0, high=1.0, high_open=True)
    limit = None if time_limit is None else as_positive(f"{w} time_limit", time_limit)
    as_flag(f"{w} prune", prune)
    if isinstance(exclude, AssignmentSolution) or not all(
        isinstance(h, AssignmentSolution) for h in exclude
    ):
        raise ProblemError(f"{w} exclude: expected a sequence of AssignmentSolution")
    kind = as_choice(f"{w} model", model, ("auto", "decomposed", "cvxpy"))
    return key, gap, limit, kind


def _decomposed_applies(
    data: AssignmentData,
    key: str,
    fixed_partition: Partition | None,
    exclude: Sequence[AssignmentSolution],
    prune: bool,
    options: dict[str, Any],
) -> bool:
    """Whether the decomposed path is exact and applies: solver HIGHS (``highspy``
    importable), no ``fixed_partition``, ``exclude`` or solver options other than
    ``verbose``, ``prune=True``, the default likelihood and prior."""
    return (
        key == "HIGHS"
        and fixed_partition is None
        and not exclude
        and prune is True
        and not set(options) - {"verbose"}
        and data.log_likelihood is None
        and data.block_log_prior is None
        and highspy_module() is not None
    )
