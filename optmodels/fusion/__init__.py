r"""Fusion of two estimates and the accuracy of its weight matrix (paper 003, Kulyavets et al.).

Paper: ``shared/papers/003_081094e0fa70fc4e.txt``, equations (1)-(14).

Problem as posed
----------------
Two independent measurers estimate the same state :math:`\alpha \in R^m`:
:math:`\hat a_\mu` with error covariance :math:`S_\mu = C_\mu^{-1}` (:math:`C_\mu` the
precision). The fused estimate (1)-(2) is the weighted least-squares solution

.. math::
    \hat a_p = \arg\min_\alpha \sum_\mu (\alpha - \hat a_\mu)^T C_\mu (\alpha - \hat a_\mu)
             = \hat a_1 + W(\hat a_2 - \hat a_1),\qquad
    W = (C_1 + C_2)^{-1} C_2 = I - C_p^{-1} C_1 \;(6) = S_1 (S_1 + S_2)^{-1}.

When :math:`S_\mu` are replaced by sample covariances :math:`\hat S_\mu` of :math:`n_\mu`
snapshots (3), :math:`\hat W` is random. The paper linearises :math:`\mathrm{vec}\,\hat W`
in :math:`\mathrm{vec}\,\hat S_\mu` (7)-(8) with the Jacobians (13)-(14)

.. math::
    \partial W/\partial (S_1)_{ij} = (I - W) E_{ij} C_1 W,\qquad
    \partial W/\partial (S_2)_{ij} = -W E_{ij} C_2 (I - W),

i.e. :math:`P_1 = (C_1W)^T \otimes (I - W)`, :math:`P_2 = -(C_2(I-W))^T \otimes W` with
``vec`` stacking columns, and propagates the Wishart moments (4)-(5) of :math:`\hat S_\mu`
through them (10).

Entry points: :func:`weight_matrix`, :func:`fuse` (closed form or CVXPY),
:func:`weight_jacobians` (closed form (13)-(14) or CasADi AD), :func:`sample_covariance_moments`
((4)-(5), known or sample mean), :func:`weight_covariance` ((10)) and
:func:`monte_carlo_weight`. Errata: ``docs/errata.md``.

Layout (one idea per module; each imports only :mod:`optmodels.core`,
:mod:`optmodels.backends` and this package):

* :mod:`~optmodels.fusion.inputs`: argument checks (S_μ, n, ``mean``, the size guard);
* :mod:`~optmodels.fusion.solution`: :class:`FusionSolution` and its failure form;
* :mod:`~optmodels.fusion.verify`: the NumPy re-check (forward error bounds, the WLS
  objective (1), the status gate, the end of every :func:`fuse`);
* :mod:`~optmodels.fusion.weights`: W (2), (6), the correlated W, the fused covariance;
* :mod:`~optmodels.fusion.closedform`: the closed forms of :func:`fuse` (1)-(2), (6) and
  the correlated (Bar-Shalom-Campo) W;
* :mod:`~optmodels.fusion.generic`: :func:`fuse` (1)-(2), closed form or CVXPY (the
  generic formulations);
* :mod:`~optmodels.fusion.accuracy`: the Jacobians (13)-(14), the moments (4)-(5), (10);
* :mod:`~optmodels.fusion.sampling`: the Monte Carlo law of Ŵ and Ŵ from snapshots;
* :mod:`~optmodels.fusion.two_site`: the two-site system (geometry, estimators,
  covariances, CRB, fusion of its estimators);
* :mod:`~optmodels.fusion.two_site_ml`: its joint ML (CasADi/IPOPT NLP and cache,
  Gauss-Newton).

Only the public API (``__all__``) is re-exported here; constants and helpers are reached
in the module that defines them (``fusion.inputs.MAX_DIM``, ``fusion.sampling.MC_CHUNK``;
to patch a constant, patch that submodule).
"""

from optmodels.fusion.accuracy import (
    commutation_matrix,
    sample_covariance_moments,
    weight_covariance,
    weight_jacobians,
)
from optmodels.fusion.generic import fuse
from optmodels.fusion.sampling import monte_carlo_weight, weight_from_samples
from optmodels.fusion.solution import FusionSolution
from optmodels.fusion.two_site import TwoSiteSystem
from optmodels.fusion.two_site_ml import JointMLSolution, clear_joint_cache
from optmodels.fusion.weights import (
    fused_covariance,
    weight_matrix,
    weight_matrix_correlated,
)

__all__ = [
    "FusionSolution",
    "JointMLSolution",
    "TwoSiteSystem",
    "clear_joint_cache",
    "commutation_matrix",
    "fuse",
    "fused_covariance",
    "monte_carlo_weight",
    "sample_covariance_moments",
    "weight_covariance",
    "weight_from_samples",
    "weight_jacobians",
    "weight_matrix",
    "weight_matrix_correlated",
]
