"""Issue 25 item 4 and issue 28 item 4: the Stone Soup associator with the API's defaults
(the gate follows from the Resolution), the merge of two well-tracked aircraft below the
beam, its input checks, and a 300-aircraft MultiTargetTracker run."""

from __future__ import annotations

import math
from datetime import datetime, timedelta
from typing import Any

import numpy as np
import pytest
from stonesoup.hypothesiser.probability import PDAHypothesiser
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.types.detection import Detection
from stonesoup.types.state import GaussianState
from stonesoup.types.track import Track

from optmodels import assignment as asg
from optmodels.assignment.polar import polar_measurement_covs
from optmodels.assignment.sensor import Resolution
from optmodels.assignment.stonesoup import MergedDetection, MergedMeasurementAssociator
from optmodels.core import ProblemError
from solvers_cmp import assignment_tracking as at

T0 = datetime(2026, 1, 1)
CELL = Resolution(range=150.0, azimuth=math.radians(1.0), site=np.zeros(2))
LAM = 1e-9


def _assoc(**kw: Any) -> MergedMeasurementAssociator:
    comps = at._components(1.0)
    return MergedMeasurementAssociator(
        PDAHypothesiser(
            comps["predictor"], comps["updater"], clutter_spatial_density=LAM, prob_detect=0.9
        ),
        resolution=CELL,
        **kw,
    )


def _track(pos: np.ndarray, sd: float, when: datetime) -> Track:
    x = np.array([pos[0], 0.0, pos[1], 0.0]).reshape(-1, 1)
    return Track([GaussianState(x, np.diag([sd**2, 1.0, sd**2, 1.0]), timestamp=when)])


def _merge_case() -> tuple[list[Track], list[Detection], datetime]:
    """Two well-tracked aircraft (σ 20 m) at 50 km, 0.5° apart in a 1° beam, one return
    between them (their centroid) and nothing else."""
    when = T0 + timedelta(seconds=1)
    r, half = 50e3, math.radians(0.25)
    pos = [r * np.array([math.cos(a), math.sin(a)]) for a in (-half, half)]
    tracks = [_track(p, 20.0, T0) for p in pos]
    z = 0.5 * (pos[0] + pos[1])
    rz = polar_measurement_covs(z[None], np.zeros(2), 30.0, math.radians(0.15))[0]
    det = Detection(
        z.reshape(-1, 1), timestamp=when, measurement_model=LinearGaussian(4, (0, 2), rz)
    )
    return tracks, [det], when


def test_merge_below_the_beam_with_the_defaults() -> None:
    """With its defaults (those of the API: no group_gate, any group size; the gate from
    the Resolution) the associator merges the two tracks on the one return: both get a
    MergedDetection of it. The merge's score beats the best resolved hypothesis,
    computed independently by brute force over every hypothesis of the same scan; the
    former default group_gate=10 excluded it."""
    tracks, dets, when = _merge_case()
    a = _assoc()
    assert a.group_gate is None and a.max_group_size is None
    hyps = a.associate(set(tracks), set(dets), when)
    got = [hyps[t].measurement for t in tracks]
    assert all(isinstance(m, MergedDetection) and m.merged_from is dets[0] for m in got)
    assert len(a.last_groups) == 1 and set(a.last_groups[0]) == set(tracks)
    sol = a.last_solution
    order = a.last_tracks
    means = np.array([[t.state_vector[0, 0], t.state_vector[2, 0]] for t in order])
    # the same scan's AssignmentData, solved by the paper's enumeration
    _, m, k = a.predict_measurements(order, dets, when)
    data = asg.AssignmentData(
        m,
        k,
        np.asarray(dets[0].state_vector, float).reshape(1, 2),
        dets[0].measurement_model.covar()[None],
        volume=1 / LAM,
        pd=0.9,
        sensor=CELL,
    )
    bf = asg.brute_force(data)
    assert bf.partition == [(0, 1)] and sol.log_score == pytest.approx(bf.log_score, rel=1e-9)
    resolved = asg.brute_force(
        asg.AssignmentData(
            m,
            k,
            data.measurements,
            data.meas_cov,
            volume=1 / LAM,
            pd=0.9,
            sensor=CELL,
            max_group_size=1,
        )
    )
    assert bf.log_score > resolved.log_score + 5.0
    assert np.linalg.norm(means[0] - means[1]) > 400.0
    old = _assoc(group_gate=10.0)  # the former default: the merge is outside its gate
    old_h = old.associate(set(tracks), set(dets), when)
    assert not old.last_groups and sum(bool(old_h[t]) for t in tracks) == 1


def test_associator_inputs_are_checked() -> None:
    """Issue 28: detections of mixed dimension, a non-numeric prob_detect or
    clutter_density, a missing timestamp (the call's or a detection's), a non-detection:
    one ProblemError naming the argument each."""
    tracks, dets, when = _merge_case()
    comps = at._components(1.0)
    hyp = PDAHypothesiser(
        comps["predictor"], comps["updater"], clutter_spatial_density=LAM, prob_detect=0.9
    )
    with pytest.raises(ProblemError, match="prob_detect"):
        MergedMeasurementAssociator(hyp, prob_detect="high")
    with pytest.raises(ProblemError, match="clutter_density"):
        MergedMeasurementAssociator(hyp, clutter_density=[1e-9])
    a = _assoc()
    three = Detection(
        np.array([[1.0], [2.0], [3.0]]),
        timestamp=when,
        measurement_model=LinearGaussian(4, (0, 1, 2), np.eye(3)),
    )
    with pytest.raises(ProblemError, match=r"detections\[1\].*mixed dimension"):
        a.associate(tracks, [dets[0], three], when)
    with pytest.raises(ProblemError, match="timestamp"):
        a.associate(set(tracks), set(dets), None)
    bare = Detection(
        dets[0].state_vector, timestamp=None, measurement_model=dets[0].measurement_model
    )
    with pytest.raises(ProblemError, match=r"detections\[0\]: has no timestamp"):
        a.associate(tracks, [bare], when)
    with pytest.raises(ProblemError, match=r"detections\[0\]: expected a Stone Soup"):
        a.associate(tracks, [np.zeros(2)], when)


@pytest.mark.slow
def test_tracker_runs_300_aircraft_for_20_scans() -> None:
    """Stone Soup's MultiTargetTracker with the associator (defaults, the radar's cell) on
    300 aircraft over a 20-200 km annulus (15 close pairs flying side by side below the
    cell), P_D 0.9, clutter, 5 s scans: 20 scans complete, every scan's MAP is proven
    optimal, merged groups are formed, and at the end ≥ 97 % of the tracks are within 3
    single-return cross-range σ of their aircraft, none farther than 5 km."""
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.tracker.simple import MultiTargetTracker

    rng = np.random.default_rng(25)
    q, pairs, dt = 300, 15, 5.0
    r = np.sqrt(rng.uniform(20e3**2, 190e3**2, q - pairs))
    az = rng.uniform(-math.pi, math.pi, q - pairs)
    p0 = r[:, None] * np.column_stack([np.cos(az), np.sin(az)])
    host = rng.choice(q - pairs, pairs, replace=False)
    side = np.column_stack([-np.sin(az[host]), np.cos(az[host])])
    p0 = np.vstack([p0, p0[host] + side * rng.uniform(100, 400, (pairs, 1))])
    vel = rng.normal(0, 150.0, (q, 2))
    vel[q - pairs :] = vel[host]  # the partners fly with their hosts
    comps = at._components(1.0)
    tracks = [_track(p0[j], 50.0, T0) for j in range(q)]
    for t, v in zip(tracks, vel, strict=True):
        t.states[0].state_vector[1, 0], t.states[0].state_vector[3, 0] = v
    from tests.test_assignment_stonesoup import _KnownStart

    scans = []
    for s in range(1, 21):
        when = T0 + timedelta(seconds=s * dt)
        truth = p0 + vel * s * dt
        dets = set()
        for j in range(q):
            if rng.uniform() < 0.9:
                pol = np.array([np.hypot(*truth[j]), math.atan2(truth[j, 1], truth[j, 0])])
                pol += rng.normal(0, [30.0, math.radians(0.15)])
                z = pol[0] * np.array([math.cos(pol[1]), math.sin(pol[1])])
                rz = polar_measurement_covs(z[None], np.zeros(2), 30.0, math.radians(0.15))[0]
                dets.add(
                    Detection(
                        z.reshape(-1, 1),
                        timestamp=when,
                        measurement_model=LinearGaussian(4, (0, 2), rz),
                        metadata={"source": j},
                    )
                )
        scans.append((when, dets))
    assoc = MergedMeasurementAssociator(
        PDAHypothesiser(
            comps["predictor"], comps["updater"], clutter_spatial_density=LAM, prob_detect=0.9
        ),
        resolution=CELL,
    )
    tracker = MultiTargetTracker(
        initiator=_KnownStart(start=tracks),
        deleter=UpdateTimeStepsDeleter(1000),
        detector=[(T0, set()), *scans],  # the tracks start here
        data_associator=assoc,
        updater=comps["updater"],
    )
    merged, done = 0, -1
    for _ in tracker:
        done += 1
        if done == 0:
            continue
        assert assoc.last_solution is not None and assoc.last_solution.status.value == "optimal"
        merged += len(assoc.last_groups)
    assert done == 20 and merged > 0
    final = p0 + vel * 20 * dt
    err = np.array(
        [
            np.linalg.norm(np.array([t.state_vector[0, 0], t.state_vector[2, 0]]) - final[j])
            for j, t in enumerate(tracks)
        ]
    )
    # a single return's cross-range σ at the aircraft's range bounds the filtered error:
    # beyond 3 of them (P < 1 % per coordinate for a consistent filter) on ≤ 3 % of tracks
    sigma = np.maximum(30.0, np.linalg.norm(final, axis=1) * math.radians(0.15))
    assert np.mean(err < 3 * sigma) >= 0.97, np.sort(err / sigma)[-10:]
    assert np.max(err) < 5e3  # no track lost to another aircraft
