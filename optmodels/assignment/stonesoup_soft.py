r"""A Stone Soup data associator with soft association over paper 004's joint hypotheses
with merged measurements (issue 29): a JPDA in which a detection may also come from an
unresolved group of tracks (optional dependency ``stonesoup``).

:class:`SoftMergedAssociator` takes the keywords of
:class:`~optmodels.assignment.stonesoup.MergedMeasurementAssociator` (it subclasses it:
``hypothesiser``, ``prob_detect``, ``clutter_density``, ``resolution``, ``rho``,
``merges``, ``cell_information``, ``information_split``, ``max_group_size``,
``group_gate``; the same defaults except ``max_group_size=3`` and ``group_gate=10``, kept
here because :func:`~optmodels.assignment.soft.soft_marginals` weighs every subset) plus
the gate, and returns
``{track: MultipleHypothesis}`` like Stone Soup's ``JPDA``, for
``MultiTargetMixtureTracker`` unchanged::

    associator = SoftMergedAssociator(PDAHypothesiser(predictor, updater,
                                                      clutter_spatial_density=lam,
                                                      prob_detect=0.9, prob_gate=0.9999),
                                      resolution=cell)
    tracker = MultiTargetMixtureTracker(initiator, deleter, detector, associator, updater)

Per scan: each track's prediction, the scan's
:class:`~optmodels.assignment.data.AssignmentData` in the measurement space (as the MAP
associator builds it), the marginals :func:`~optmodels.assignment.soft.soft_marginals`,
and per track one ``SingleProbabilityHypothesis`` for the miss (probability β_j(·, −1)
summed over its blocks), one per resolved detection β_j((j,), i), and one per merged
(S, i) with a :class:`~optmodels.assignment.stonesoup.MergedDetection` (the centroid
pseudo-measurement update, with the cell information and the information split as in the
MAP associator). The tracker updates each and reduces the mixture by moment matching
(``gm_reduce_single``; ``docs/formulations.md``).

Gate (``gate``, Mahalanobis distance of a detection to a block's predicted return, and
``prob_gate`` P_G): by default the hypothesiser's (a ``PDAHypothesiser``: its
``prob_gate`` and the gate √χ²_d(P_G), none with ``include_all``), so that with merges
impossible the associator is Stone Soup's JPDA with that hypothesiser, to round-off. The
*effective* gate of the soft update is softer than any hard one: a lone detection at
distance d gets the weight 1/(1 + e^{(d² − d*²)/2}),
:func:`~optmodels.assignment.soft.effective_gate`; give ``gate=5`` (GNN's) or a
``prob_gate`` near 1 to keep detections that a bad track's prediction places far out.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.stats import chi2

from optmodels.assignment.data import AssignmentData
from optmodels.assignment.sensor import Resolution
from optmodels.assignment.soft import (
    MAX_ENUMERATED,
    SoftMarginals,
    chi2_gate_probability,
    soft_marginals,
)
from optmodels.assignment.stonesoup import (
    MergedDetection,
    MergedMeasurementAssociator,
    cell_covariance,
    merged_update_inputs,
)
from optmodels.core import ProblemError, as_count, as_finite_array, as_positive, as_probability

try:
    from stonesoup.base import Property
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.detection import MissedDetection
    from stonesoup.types.hypothesis import SingleProbabilityHypothesis
    from stonesoup.types.multihypothesis import MultipleHypothesis
    from stonesoup.types.numeric import Probability
except ImportError as _exc:  # pragma: no cover - exercised only without Stone Soup
    raise ImportError(
        "optmodels.assignment.stonesoup_soft needs Stone Soup: "
        "pip install 'optmodels[peers]' (stonesoup)"
    ) from _exc

__all__ = ["SoftMergedAssociator"]

_W = "assignment.SoftMergedAssociator"


def _chain(resolution: Resolution, means: np.ndarray) -> list[int]:
    """Members ordered along the cell's chain (by range from the site for a polar cell,
    along the principal axis for an ellipse), as the MAP associator orders them."""
    if resolution.ellipse is None:
        site = np.zeros(means.shape[1]) if resolution.site is None else resolution.site
        key = np.linalg.norm(means - site, axis=1)
    else:
        c = means - means.mean(axis=0)
        key = c @ np.linalg.svd(c, full_matrices=False)[2][0]
    return [int(b) for b in np.argsort(key, kind="stable")]


def _with_noise(model: Any, noise: np.ndarray) -> Any:
    import copy

    m = copy.copy(model)
    try:
        m.noise_covar = CovarianceMatrix(noise)
    except AttributeError:
        raise ProblemError(
            f"{_W}: the measurement model {type(model).__name__} has no "
            f"noise_covar to inflate for a merged detection"
        ) from None
    return m


class SoftMergedAssociator(MergedMeasurementAssociator):
    """Soft (JPDA-style) association with merged measurements (module docstring).

    After each call ``last_marginals`` holds the :class:`~optmodels.assignment.soft.
    SoftMarginals` (object indices index ``last_tracks``)."""

    max_group_size: int = Property(default=3, doc="Largest unresolved group considered")
    group_gate: float = Property(
        default=10.0,
        doc="Members of a candidate group pairwise within this Mahalanobis "
        "distance of each other's predicted measurements (None: no gate)",
    )
    gate: float = Property(
        default=None,
        doc="Hard gate, Mahalanobis distance of a detection to a block's "
        "predicted return; None: the hypothesiser's (PDAHypothesiser: "
        "√χ²_d(prob_gate), none with include_all; else none)",
    )
    prob_gate: float = Property(
        default=None,
        doc="P_G: an undetected block has the prior 1 − P_D P_G; None: the "
        "hypothesiser's prob_gate, else P(χ²_d ≤ gate²), else 1",
    )
    prune: float = Property(default=1e-14, doc="soft_marginals' prune bound")
    max_enumerated: int = Property(
        default=MAX_ENUMERATED, doc="Enumerate clusters up to this many hypotheses"
    )
    k: int = Property(default=100, doc="k best per cluster beyond max_enumerated")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if self.gate is not None:
            self.gate = as_positive(f"{_W} gate", self.gate, allow_inf=True)
        if self.prob_gate is not None:
            self.prob_gate = as_probability(f"{_W} prob_gate", float(self.prob_gate), low_open=True)
        self.prune = float(as_probability(f"{_W} prune", self.prune))
        self.max_enumerated = as_count(f"{_W} max_enumerated", self.max_enumerated, minimum=1)
        self.k = as_count(f"{_W} k", self.k, minimum=1)
        self.last_marginals: SoftMarginals | None = None

    def _meas_model(self, detection: Any) -> Any:
        """The detection's measurement model, else the updater's."""
        model = getattr(detection, "measurement_model", None)
        return model if model is not None else self.hypothesiser.updater.measurement_model

    def gate_parameters(self, d: int) -> tuple[float | None, float]:
        """(gate, P_G) in a d-dimensional measurement space (class docstring)."""
        h = self.hypothesiser
        gate, pg = self.gate, self.prob_gate
        h_pg = getattr(h, "prob_gate", None)
        if gate is None and h_pg is not None and not getattr(h, "include_all", False):
            gate = float(np.sqrt(chi2.ppf(float(h_pg), d)))
        elif gate is None and getattr(h, "missed_distance", None) is not None:
            gate = float(h.missed_distance)  # a DistanceHypothesiser (Mahalanobis)
        if pg is None:
            if h_pg is not None:
                pg = float(h_pg)
            elif gate is not None and np.isfinite(gate):
                pg = chi2_gate_probability(gate, d)
            else:
                pg = 1.0
        return gate, pg

    def associate(
        self, tracks: Any, detections: Any, timestamp: Any, **kwargs: Any
    ) -> Mapping[Any, Any]:
        """``{track: MultipleHypothesis}`` (normalised, the miss first) for ``tracks`` and
        ``detections`` at ``timestamp`` (module docstring)."""
        tracks = list(tracks)
        dets = list(detections)
        self.last_marginals, self.last_tracks = None, tracks
        self.last_solution, self.last_groups = None, []
        if not tracks:
            return {}
        preds, means, covs = self.predict_measurements(tracks, dets, timestamp, **kwargs)
        d = means.shape[1]
        if not dets:
            return {
                tr: MultipleHypothesis(
                    [
                        SingleProbabilityHypothesis(
                            p, MissedDetection(timestamp=timestamp), probability=Probability(1.0)
                        )
                    ],
                    True,
                    1,
                )
                for tr, p in zip(tracks, preds, strict=True)
            }
        z = np.array([np.asarray(dt.state_vector, dtype=float).ravel() for dt in dets]).reshape(
            len(dets), d
        )
        z = as_finite_array(f"{_W} detections", z, shape=(len(dets), d))
        noises = np.array(
            [np.asarray(self._meas_model(dt).covar(), dtype=float) for dt in dets]
        ).reshape(len(dets), d, d)
        sensor = self.resolution if self.merges else None
        data = AssignmentData(
            means,
            covs,
            z,
            noises,
            volume=1.0 / float(self.clutter_density),
            pd=float(self.prob_detect),
            rho=None if sensor is not None else float(self.rho),
            sensor=sensor,
            max_group_size=int(self.max_group_size) if self.merges else 1,
            group_gate=self.group_gate if self.merges else None,
        )
        gate, pg = self.gate_parameters(d)
        marg = soft_marginals(
            data,
            gate=gate,
            prob_gate=pg,
            prune=self.prune,
            max_enumerated=self.max_enumerated,
            k=self.k,
        )
        self.last_marginals = marg
        # one pseudo-detection per member of every merged (S, i) with mass
        merged: dict[tuple[tuple[int, ...], int], dict[int, MergedDetection]] = {}
        for j in range(len(tracks)):
            for (s, i), _ in marg.beta[j].items():
                if len(s) > 1 and i >= 0 and (s, i) not in merged:
                    merged[(s, i)] = self._merged(s, i, dets[i], means, covs, z, noises)
        out: dict[Any, Any] = {}
        for j, tr in enumerate(tracks):
            miss = marg.miss(j)
            hyps = [
                SingleProbabilityHypothesis(
                    preds[j], MissedDetection(timestamp=timestamp), probability=Probability(miss)
                )
            ]
            for (s, i), b in sorted(marg.beta[j].items(), key=lambda x: (x[0][1], x[0][0])):
                if i < 0:
                    continue
                det = dets[i] if len(s) == 1 else merged[(s, i)][j]
                hyps.append(SingleProbabilityHypothesis(preds[j], det, probability=Probability(b)))
            out[tr] = MultipleHypothesis(hyps, True, 1)
        return out

    def _merged(
        self,
        s: tuple[int, ...],
        i: int,
        det: Any,
        means: np.ndarray,
        covs: np.ndarray,
        z: np.ndarray,
        noises: np.ndarray,
    ) -> dict[int, MergedDetection]:
        """The members' pseudo-detections of detection ``i`` from the merged block ``s``
        (the MAP associator's centroid update: cell information, information split)."""
        members = list(s)
        w = np.full(len(members), 1.0 / len(members))
        cell = None
        if self.cell_information and self.resolution is not None:
            cell = cell_covariance(self.resolution, w @ means[members])
            members = [members[b] for b in _chain(self.resolution, means[members])]
        zs, rs = merged_update_inputs(z[i], means[members], covs[members], noises[i], w, cell)
        if self.information_split:
            rs = rs * len(members)
        model = self._meas_model(det)
        return {
            j: MergedDetection(
                StateVector(zs[b]),
                timestamp=det.timestamp,
                measurement_model=_with_noise(model, rs[b]),
                metadata=dict(det.metadata),
                merged_from=det,
                group_size=len(members),
                weight=float(w[b]),
            )
            for b, j in enumerate(members)
        }
