r"""The result of paper 004's joint assignment: the hypothesis H = (π, γ) of (13)-(14)
found, its score (13) and its failure form.

:class:`AssignmentSolution` is what every solver of the package returns (the generic
:func:`optmodels.assignment.solve`, :func:`~optmodels.assignment.brute_force`,
:func:`~optmodels.assignment.linear_assignment`, :func:`~optmodels.assignment.k_best`);
:func:`_failure` is the form of a result the gate refused
(:func:`optmodels.assignment.verify._finish`); :func:`_canonical` is the hypothesis in
the solution's canonical order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from optmodels.assignment.data import Partition
from optmodels.core import Solution, failure


@dataclass
class AssignmentSolution(Solution):
    """``partition`` (sorted list of sorted tuples), ``assignment`` (N,) index into
    ``partition`` or −1 (background), ``log_score``, ``mip_gap`` reached."""

    partition: Partition = field(default_factory=list)
    assignment: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=int))
    log_score: float = float("nan")
    mip_gap: float | None = None


def _failure(sol: AssignmentSolution, mip_gap: float | None) -> AssignmentSolution:
    """The failure form of an assignment solution (:func:`optmodels.core.failure`): no
    hypothesis (empty partition and assignment, score NaN), the MIP gap the solver
    reached (``mip_gap``); the refused hypothesis is kept in ``info["rejected_partition"]``
    and ``info["rejected_assignment"]``, its residuals in ``residuals``."""
    return failure(
        AssignmentSolution,
        sol.method,
        sol.message,
        status=sol.status,
        build_time=sol.build_time,
        solve_time=sol.solve_time,
        iterations=sol.iterations,
        mip_gap=mip_gap,
        residuals=sol.residuals,
        info=dict(sol.info, rejected_partition=sol.partition, rejected_assignment=sol.assignment),
    )


def _canonical(
    partition: Sequence[Sequence[int]], assignment: Sequence[int] | np.ndarray
) -> tuple[Partition, np.ndarray]:
    """The hypothesis in a solution's canonical form: each block a sorted tuple, the blocks
    in sorted order, ``assignment`` (block index or −1) re-indexed to that order."""
    blocks = [tuple(sorted(b)) for b in partition]
    order = sorted(range(len(blocks)), key=lambda k: blocks[k])
    new_index = {old: new for new, old in enumerate(order)}
    return [blocks[k] for k in order], np.array(
        [new_index[k] if k >= 0 else -1 for k in assignment], dtype=int
    )
