r"""ML joint assignment of measurements to closely spaced objects that may be unresolved,
with clutter (paper 004, Logachev, Khudov, Shchennikov), as one integer program.

Paper: ``shared/papers/004_ce4b6db66d57cef7.txt``. The paper's rule (13)-(14) enumerates
every unresolved variant (a set partition π of the Q objects) and every identification
matrix γ; optmodels solves the same maximisation exactly as one MILP.

The package is in the one skeleton (``docs/architecture.md``, "Adding a problem"): the
data and the model (the paper leaves the group likelihood and the prior open; a default is
given) in :mod:`~optmodels.assignment.data`, the result in
:mod:`~optmodels.assignment.solution`, the re-check and gate in
:mod:`~optmodels.assignment.verify`, the generic MILP solve in
:mod:`~optmodels.assignment.generic` (no closed form: the paper's method is the
enumeration :func:`brute_force`). Modules, each importing only :mod:`optmodels.core`,
:mod:`optmodels.backends` and the ones above it:

* :mod:`~optmodels.assignment.quadrature`: the Gaussian mass on a resolution cell
  (Gauss–Legendre quadrature);
* :mod:`~optmodels.assignment.polar`: :func:`cartesian_to_polar`,
  :func:`polar_to_cartesian`, the polar measurement covariances
  :func:`polar_measurement_covs`;
* :mod:`~optmodels.assignment.merge_prior`: the chain prior of a merged group,
  :func:`connected_probability` and ln w(S);
* :mod:`~optmodels.assignment.sensor`: the sensor's resolution model :class:`Resolution`
  (the probability that a group is unresolved, from the members' predicted separation and
  uncertainty; the paper's constant ρ as a special case) and the gated pair table
  :class:`PairTable`;
* :mod:`~optmodels.assignment.data`: :class:`AssignmentData`, the likelihoods (5), the
  prior, :func:`score` (13);
* :mod:`~optmodels.assignment.groups`: :func:`candidate_groups` (the MILP's z_S columns);
* :mod:`~optmodels.assignment.solution`: :class:`AssignmentSolution` and its failure form;
* :mod:`~optmodels.assignment.verify`: the NumPy re-check of a MILP point and the gate;
* :mod:`~optmodels.assignment.hypotheses`: counting and enumerating hypotheses (14),
  :func:`brute_force` (the paper's method);
* :mod:`~optmodels.assignment.solvers`: MILP solver names, gap/time-limit options, the
  HiGHS banner;
* :mod:`~optmodels.assignment.milp`: the sparse CVXPY MILP and its exact pruning (the
  original form);
* :mod:`~optmodels.assignment.gating` and :mod:`~optmodels.assignment.decomposed`: the
  scale path of :func:`solve` (the model's gate, exact pruning on the gated entries, the
  exact split into connected components, closed forms and one direct HiGHS model per
  scan; issue 25);
* :mod:`~optmodels.assignment.generic`: :func:`solve` (either path);
* :mod:`~optmodels.assignment.linear`: :func:`linear_assignment` (merges disallowed);
* :mod:`~optmodels.assignment.kbest`: :func:`k_best`, :class:`KBest` (marginals);
* :mod:`~optmodels.assignment.soft`: soft association, :func:`soft_marginals` (issue 29);
* :mod:`~optmodels.assignment.stonesoup` and :mod:`~optmodels.assignment.stonesoup_soft`:
  :class:`MergedMeasurementAssociator` and ``SoftMergedAssociator``, Stone Soup data
  associators on the MAP (or the marginals) with merged measurements, usable in Stone
  Soup's trackers (optional dependency ``stonesoup``; import them from their modules).

Every public name is re-exported here (``from optmodels import assignment as asg;
asg.solve``). To monkeypatch what a function uses, patch the submodule that uses it (e.g.
``optmodels.assignment.milp.solve_problem``), not this package.
"""

from optmodels.assignment.data import MAX_TABLE_ENTRIES as MAX_TABLE_ENTRIES
from optmodels.assignment.data import (
    AssignmentData,
    block_log_prior,
    log_likelihoods,
    score,
)
from optmodels.assignment.data import Partition as Partition
from optmodels.assignment.data import group_moments as group_moments
from optmodels.assignment.decomposed import MAX_MILP_COLUMNS as MAX_MILP_COLUMNS
from optmodels.assignment.generic import solve
from optmodels.assignment.groups import MAX_CANDIDATE_GROUPS as MAX_CANDIDATE_GROUPS
from optmodels.assignment.groups import candidate_groups
from optmodels.assignment.hypotheses import BRUTE_FORCE_LIMIT as BRUTE_FORCE_LIMIT
from optmodels.assignment.hypotheses import COUNT_LIMIT as COUNT_LIMIT
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
from optmodels.assignment.merge_prior import connected_probability
from optmodels.assignment.milp import MAX_LIKELIHOOD_ENTRIES as MAX_LIKELIHOOD_ENTRIES
from optmodels.assignment.milp import MAX_MODEL_COLUMNS as MAX_MODEL_COLUMNS
from optmodels.assignment.polar import (
    cartesian_to_polar,
    polar_measurement_covs,
    polar_to_cartesian,
)
from optmodels.assignment.sensor import PAIR_NEGLECT as PAIR_NEGLECT
from optmodels.assignment.sensor import PairTable as PairTable
from optmodels.assignment.sensor import Resolution
from optmodels.assignment.solution import AssignmentSolution
from optmodels.assignment.solvers import MILP_SOLVERS as MILP_SOLVERS

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
