r"""Plane of maneuver by maximum likelihood (paper 000, Korobochkin).

Paper: ``shared/papers/000_9c0f4a5f1246cc76.txt``, equations (1.1)-(1.17).

Problem as posed
----------------
Measured positions :math:`x_i^* = x_i + \xi_i`, :math:`\xi_i \sim N(0, D_i)` independent,
:math:`i = 1..N`. The plane is :math:`\langle n, x\rangle = a`, :math:`\|n\| = 1` (1.1).
Maximum likelihood gives the non-convex program in :math:`3N + 4` unknowns

.. math::
    F = \sum_i (x_i - x_i^*)^T D_i^{-1} (x_i - x_i^*) \to \min_{x_i, n, a}      (1.2)

    \langle n, x_i\rangle - a = 0,\ i = 1..N, \qquad n_1^2 + n_2^2 + n_3^2 = 1     (1.3)

Reductions
----------
* Fixing ``(n, a)`` the problem splits into N projections; the minimum of each is
  :math:`\varphi_i = (a - \langle n, x_i^*\rangle)^2 / \langle D_i n, n\rangle` (1.11),
  reached at the oblique projection (1.8). So (1.2)-(1.3) is equivalent to the
  4-variable problem :math:`\sum_i \varphi_i(a, n) \to \min`, :math:`\|n\|=1`
  (1.12)-(1.13), for **any** SPD :math:`D_i`.
* If :math:`D_i = \alpha_i^2 D` (1.4), minimising over ``a`` gives (1.7) and the Rayleigh
  quotient :math:`n^T Q n / n^T D n` (1.14)-(1.15) with the weighted scatter ``Q`` (1.5):
  the plane normal is the generalized eigenvector of ``(Q, D)`` of the smallest
  eigenvalue, found along the paper's route ``D = h M h^T``, ``R = M^{-1/2} h^T Q h
  M^{-1/2} = g \Lambda g^T``, ``n \propto h M^{-1/2} g_k`` (1.6), and
  :math:`\min F = \Lambda_{\min}` (1.16).

Entry points
------------
:func:`solve` (``formulation="full"`` (1.2)-(1.3) or ``"reduced"`` (1.12)-(1.13), CasADi +
IPOPT), :func:`closed_form` (1.5)-(1.8), :func:`svd_fit` (unweighted total least squares,
the baseline), :func:`planarity_test` (χ² test, with the paper's rule (1.17) beside it),
:func:`identify_sequence` (running estimate as in the paper's example),
:func:`cramer_rao_bound`.

Errata (details and the tests that show them in ``docs/errata.md``)
--------------------------------------------------------------------
* (1.17): the statistic :math:`\Lambda_{\min}` is :math:`\chi^2` with ``N - 3`` degrees
  of freedom, not ``N`` (three plane parameters are fitted), and the Fisher approximation
  gives :math:`\sqrt{2\chi^2} \approx N(\sqrt{2k-1}, 1)`: the margin ``+2`` is the
  0.977 quantile, not 0.997 (which needs 2.75). The printed rule raises false alarms
  about 2% of the time (at N = 1000), not 0.3%. Valid only when the plane is resolved
  (a short, nearly straight arc gives a statistic below :math:`\chi^2_{N-3}`).
* The change of basis after (1.15) is :math:`B = g^T M^{1/2} h^T`, not :math:`M^{-1/2}`.
* The number (1.7) is used twice (for ``R`` and for ``a``); the reference before (1.16)
  is broken in the source ("Ошибка! Источник ссылки не найден").
* ``a`` is called "the distance to the origin"; it is a signed distance (``n`` and ``a``
  are defined up to a common sign). optmodels reports ``offset >= 0``.

Package layout
--------------
The skeleton of every problem package (``docs/architecture.md``, "Adding a problem"):

* :mod:`~optmodels.plane.data`: :class:`PlaneData` and the original form in NumPy
  (objective (1.2), residuals of (1.3), (1.11)-(1.12), (1.8)).
* :mod:`~optmodels.plane.solution`: :class:`PlaneSolution` and its failure form.
* :mod:`~optmodels.plane.verify`: the re-check of every estimate against (1.2)-(1.3) and
  the gate.
* :mod:`~optmodels.plane.generic`: the NLPs in the back-end's cache and the multistart
  :func:`solve`; their CasADi formulations (full (1.2)-(1.3) with its O(N) derivatives,
  reduced (1.12)-(1.13)) in :mod:`~optmodels.plane.formulations`.
* :mod:`~optmodels.plane.closedform`: :func:`closed_form` (1.5)-(1.8),
  :func:`change_of_basis`, :func:`scatter_matrix`, :func:`svd_fit`.

The problem's own modules:

* :mod:`~optmodels.plane.statistics`: :func:`planarity_test`, :func:`cramer_rao_bound`,
  :func:`angle_error`, :func:`plane_errors`.
* :mod:`~optmodels.plane.sequence`: :func:`identify_sequence`.
* :mod:`~optmodels.plane.tracking`: :func:`track` / :class:`PlaneTrack`, the plane on a
  stream: sliding windows (:mod:`~optmodels.plane.windows`, running sums with removal), the
  plane-change test (:mod:`~optmodels.plane.detector`: a Chow-type likelihood-ratio test
  with its false-alarm rate per hour bounded, and the detectable tilt), general D_i
  through :func:`fit_general` (its argument checks in :mod:`~optmodels.plane.track_setup`,
  its steps in :mod:`~optmodels.plane.track_steps`). Named ``tracking`` so that it does
  not shadow the function.
* :mod:`~optmodels.plane.general`: :func:`fit_general`, the ML plane for general SPD D_i
  (Newton on the sphere for the profile of (1.12)), warm-startable;
  :mod:`~optmodels.plane.lines`: :func:`line_test`, the resolved test;
  :mod:`~optmodels.plane.radar`: :func:`radar_covariances` (range, azimuth,
  elevation noise → ENU, first order), :func:`to_polar`, :func:`from_polar`.
* :mod:`~optmodels.plane.simulate`: :func:`plane_change_track` and the Monte Carlo helpers
  of the detector.
"""

from optmodels.plane.closedform import change_of_basis as change_of_basis
from optmodels.plane.closedform import closed_form, svd_fit
from optmodels.plane.closedform import scatter_matrix as scatter_matrix
from optmodels.plane.data import (
    PlaneData,
    constraint_residuals,
    objective,
    optimal_offset,
    project,
    reduced_objective,
)
from optmodels.plane.general import GeneralFit, LineTest, fit_general, line_test
from optmodels.plane.generic import Formulation as Formulation
from optmodels.plane.generic import clear_nlp_cache, solve
from optmodels.plane.radar import from_polar, radar_covariances, to_polar
from optmodels.plane.sequence import PlaneSequence, identify_sequence
from optmodels.plane.simulate import plane_change_track as plane_change_track
from optmodels.plane.solution import PlaneSolution
from optmodels.plane.statistics import (
    CramerRao,
    PlanarityTest,
    angle_error,
    cramer_rao_bound,
    planarity_test,
    plane_errors,
)
from optmodels.plane.tracking import PlaneTrack, track

__all__ = [
    "CramerRao",
    "GeneralFit",
    "LineTest",
    "PlanarityTest",
    "PlaneData",
    "PlaneSequence",
    "PlaneSolution",
    "PlaneTrack",
    "angle_error",
    "clear_nlp_cache",
    "closed_form",
    "constraint_residuals",
    "cramer_rao_bound",
    "fit_general",
    "from_polar",
    "identify_sequence",
    "line_test",
    "objective",
    "optimal_offset",
    "planarity_test",
    "plane_errors",
    "project",
    "radar_covariances",
    "reduced_objective",
    "solve",
    "svd_fit",
    "to_polar",
    "track",
]
