r"""ML joint assignment of measurements to closely spaced objects that may be unresolved,
with clutter (paper 004, Logachev, Khudov, Shchennikov), as one integer program.

Paper: ``shared/papers/004_ce4b6db66d57cef7.txt``. The paper's rule (13)-(14) enumerates
every unresolved variant (a set partition π of the Q objects) and every identification
matrix γ; optmodels solves the same maximisation exactly as one MILP.

The model (the paper leaves the group likelihood and the prior open; a default is given)
is in :mod:`~optmodels.assignment.data`, the MILP and its exact pruning in
:mod:`~optmodels.assignment.milp`. Modules, each importing only :mod:`optmodels.core`,
:mod:`optmodels.backends` and the ones above it:

* :mod:`~optmodels.assignment.data`: :class:`AssignmentData`, candidate groups, the
  likelihoods (5), the prior, :func:`score` (13), :class:`AssignmentSolution`, and the
  NumPy re-check of an answer;
* :mod:`~optmodels.assignment.hypotheses`: counting and enumerating hypotheses (14),
  :func:`brute_force` (the paper's method);
* :mod:`~optmodels.assignment.solvers`: MILP solver names, gap/time-limit options, the
  HiGHS banner;
* :mod:`~optmodels.assignment.milp`: :func:`solve`, the sparse MILP and its pruning;
* :mod:`~optmodels.assignment.decomposed`: the scale path of :func:`solve` (the model's
  gate, exact pruning on the gated entries, the exact split into connected components,
  closed forms and one direct HiGHS model per scan; issue 25);
* :mod:`~optmodels.assignment.linear`: :func:`linear_assignment` (merges disallowed);
* :mod:`~optmodels.assignment.kbest`: :func:`k_best`, :class:`KBest` (marginals);
* :mod:`~optmodels.assignment.sensor`: the sensor's resolution model :class:`Resolution`
  (the probability that a group is unresolved, from the members' predicted separation and
  uncertainty; the paper's constant ρ as a special case) and the polar measurement
  covariances :func:`polar_measurement_covs`;
* :mod:`~optmodels.assignment.stonesoup`: :class:`MergedMeasurementAssociator`, a Stone
  Soup data associator on the MAP with merged measurements, usable in Stone Soup's
  ``MultiTargetTracker`` (optional dependency ``stonesoup``; import it from its module).

Every name is re-exported here (``from optmodels import assignment as asg; asg.solve``).
To monkeypatch what a function uses, patch the submodule that uses it (e.g.
``optmodels.assignment.milp.solve_problem``), not this package.
"""

from optmodels.assignment.data import MAX_CANDIDATE_GROUPS as MAX_CANDIDATE_GROUPS
from optmodels.assignment.data import MAX_TABLE_ENTRIES as MAX_TABLE_ENTRIES
from optmodels.assignment.data import (
    AssignmentData,
    AssignmentSolution,
    block_log_prior,
    candidate_groups,
    log_likelihoods,
    score,
)
from optmodels.assignment.data import PairTable as PairTable
from optmodels.assignment.data import Partition as Partition
from optmodels.assignment.data import _as_assignment as _as_assignment
from optmodels.assignment.data import _as_partition as _as_partition
from optmodels.assignment.data import _canonical as _canonical
from optmodels.assignment.data import _logpdf as _logpdf
from optmodels.assignment.data import _recheck as _recheck
from optmodels.assignment.data import group_moments as group_moments
from optmodels.assignment.decomposed import MAX_MILP_COLUMNS as MAX_MILP_COLUMNS
from optmodels.assignment.hypotheses import BRUTE_FORCE_LIMIT as BRUTE_FORCE_LIMIT
from optmodels.assignment.hypotheses import COUNT_LIMIT as COUNT_LIMIT
from optmodels.assignment.hypotheses import _assignments as _assignments
from optmodels.assignment.hypotheses import _assignments_count as _assignments_count
from optmodels.assignment.hypotheses import _check_counts as _check_counts
from optmodels.assignment.hypotheses import (
    brute_force,
    count_hypotheses,
    count_per_variant,
    enumerate_hypotheses,
    set_partitions,
)
from optmodels.assignment.hypotheses import count_gated as count_gated
from optmodels.assignment.kbest import K_BEST_LIMIT as K_BEST_LIMIT
from optmodels.assignment.kbest import KBest, k_best
from optmodels.assignment.linear import linear_assignment
from optmodels.assignment.milp import MAX_LIKELIHOOD_ENTRIES as MAX_LIKELIHOOD_ENTRIES
from optmodels.assignment.milp import MAX_MODEL_COLUMNS as MAX_MODEL_COLUMNS
from optmodels.assignment.milp import _build_model as _build_model
from optmodels.assignment.milp import _prune as _prune
from optmodels.assignment.milp import solve
from optmodels.assignment.sensor import PAIR_NEGLECT as PAIR_NEGLECT
from optmodels.assignment.sensor import (
    Resolution,
    cartesian_to_polar,
    connected_probability,
    polar_measurement_covs,
    polar_to_cartesian,
)
from optmodels.assignment.solvers import MILP_SOLVERS as MILP_SOLVERS
from optmodels.assignment.solvers import _as_solver as _as_solver
from optmodels.assignment.solvers import _silence_highs_banner as _silence_highs_banner
from optmodels.assignment.solvers import _solver_options as _solver_options

__all__ = [
    "AssignmentData",
    "AssignmentSolution",
    "KBest",
    "Resolution",
    "block_log_prior",
    "brute_force",
    "candidate_groups",
    "cartesian_to_polar",
    "connected_probability",
    "count_hypotheses",
    "count_per_variant",
    "enumerate_hypotheses",
    "k_best",
    "linear_assignment",
    "log_likelihoods",
    "polar_measurement_covs",
    "polar_to_cartesian",
    "score",
    "set_partitions",
    "solve",
]

# issue 29: soft association with merged measurements (optmodels.assignment.soft; the Stone
# Soup associator is optmodels.assignment.stonesoup_soft.SoftMergedAssociator)
from optmodels.assignment.soft import (
    SoftMarginals,
    effective_gate,
    reduce_mixture,
    soft_marginals,
)

__all__ += ["SoftMarginals", "effective_gate", "reduce_mixture", "soft_marginals"]
