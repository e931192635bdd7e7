"""The metrics of one tracking run of :mod:`solvers_cmp.assignment_tracking` against its
encounter's truth (issue 18's crossing and parallel encounters, issue 29's traffic
encounters).

Metrics per run (positions only, m):

* mean GOSPA: Stone Soup's ``GOSPAMetric`` (p = 2, α = 2, cutoff ``c``) per scan,
  averaged over the scans;
* assignment of tracks to truths per scan: the optimal assignment of the GOSPA cost
  (distance, cutoff c; a pair at ≥ c is unassigned). A track's label is the truth it is
  assigned to (or none);
* track swap: a track whose label at the last scan (the objects of a crossing are then
  kilometres apart) is another object than the one it started on; counted per track
  (a swapped pair counts 2). Flips of the assignment while the objects are closer than
  the estimation errors are not swaps. In a parallel encounter below the resolution the
  objects never separate, and a "swap" there is a coin toss on unobservable identities;
* track break: a track whose label goes from an object to none (lost: farther than c
  from every object it could take), counted once per loss.

The tracks are Stone Soup ``Track`` objects whose states carry the timestamps :data:`T0` +
the encounter's times (s).
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from optmodels.scenarios.encounters import Encounter

#: The Stone Soup timestamp of an encounter's time 0.
T0 = datetime(2026, 1, 1)


def _truth_paths(enc: Encounter) -> list[Any]:
    """The encounter's truth as Stone Soup ``GroundTruthPath`` objects, one per object."""
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState

    return [
        GroundTruthPath(
            [
                GroundTruthState(
                    enc.truth[k, t].reshape(-1, 1), timestamp=T0 + timedelta(seconds=float(tt))
                )
                for t, tt in enumerate(enc.times)
            ]
        )
        for k in range(enc.q)
    ]


def gospa_per_scan(
    enc: Encounter, tracks: list[Any], *, c: float = 500.0, p: float = 2.0
) -> list[float]:
    """Stone Soup's GOSPA distance (positions, m) at each scan."""
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import GOSPAMetric

    gen = GOSPAMetric(c=c, p=p, measure=Euclidean(mapping=(0, 2)))
    m = gen.compute_over_time(
        *gen.extract_states(tracks, True), *gen.extract_states(_truth_paths(enc), True)
    )
    values = m.value if isinstance(m.value, list) else [m]
    return [float(v.value["distance"]) for v in values]


def track_labels(enc: Encounter, tracks: list[Any], *, c: float = 500.0) -> list[list[int | None]]:
    """Per scan, the object each track is assigned to by the optimal assignment of the
    GOSPA cost (position distance, cutoff ``c``; None: unassigned)."""
    out = []
    for t in range(len(enc.times)):
        est = np.array(
            [
                np.asarray(tr.states[t + 1].state_vector, dtype=float).ravel()[[0, 2]]
                for tr in tracks
            ]
        )
        tru = enc.truth[:, t][:, [0, 2]]
        cost = np.minimum(np.linalg.norm(est[:, None] - tru[None], axis=2), c)
        rows, cols = linear_sum_assignment(cost)
        label: list[int | None] = [None] * len(tracks)
        for r, k in zip(rows, cols, strict=True):
            if cost[r, k] < c:
                label[r] = int(k)
        out.append(label)
    return out


def swaps_and_breaks(enc: Encounter, tracks: list[Any], *, c: float = 500.0) -> tuple[int, int]:
    """Track swaps and breaks of a run (module docstring): swaps = tracks whose label at
    the last scan is another object than the one they started on (track j on object j);
    breaks = transitions of a track's label from an object to none (first scan included:
    tracks start on their objects)."""
    labels = track_labels(enc, tracks, c=c)
    prev: list[int | None] = list(range(len(tracks)))
    breaks = 0
    for lab in labels:
        breaks += sum(p is not None and x is None for p, x in zip(prev, lab, strict=True))
        prev = lab
    swaps = sum(x is not None and x != j for j, x in enumerate(labels[-1]))
    return swaps, breaks
