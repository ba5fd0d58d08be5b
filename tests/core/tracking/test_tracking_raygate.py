"""The ray gate (no phantom shadowing a track along its ray) and lost-but-not-ended tracks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from demtrack.core.errors import TrackingError
from demtrack.core.tracking import TrackerConfig, build_tracker
from demtrack.core.tracking.raygate import ray_gate
from demtrack.core.tracking.types import Fix

CAM = np.array([0.0, 0.0, 20.0])


def _brute_d2(o, d, mean, cov, n=200_001, s_max=400.0):
    """Smallest Mahalanobis distance over points sampled along the ray's ground track."""
    h = np.hypot(d[0], d[1])
    s = np.linspace(0.0, s_max, n)
    pts = o[:2] + s[:, None] * (d[:2] / h)
    r = pts - mean
    w = np.linalg.inv(cov)
    d2 = np.einsum("ni,ij,nj->n", r, w, r)
    k = int(np.argmin(d2))
    return float(d2[k]), float(o[2] + s[k] * d[2] / h)


def test_ray_gate_matches_a_brute_force_search_along_the_ray():
    rng = np.random.default_rng(0)
    for _ in range(50):
        d = np.array([*rng.normal(size=2), -0.1])
        mean = CAM[:2] + rng.uniform(20, 200) * d[:2] / np.hypot(*d[:2]) + rng.normal(0, 3, 2)
        a = rng.normal(size=(2, 2))
        cov = a @ a.T + 0.5 * np.eye(2)
        d2, z_ray = _brute_d2(CAM, d, mean, cov)
        for gate in (0.5 * d2, 2.0 * d2 + 1e-6):
            got = ray_gate(CAM, d, mean[None], cov[None], np.array([z_ray]), gate, 0.05)
            assert bool(got[0]) == (d2 <= gate)
        # the height test: the ray passes the track at z_ray
        far = ray_gate(CAM, d, mean[None], cov[None], np.array([z_ray + 1.0]), 1e9, 0.5)
        assert not far[0]


def test_ray_gate_analytic_case_and_behind_the_camera():
    d = np.array([1.0, 0.0, -0.2])  # along +x, 0.2 m down per metre
    cov = np.array([[[4.0, 0.0], [0.0, 1.0]]])
    # track at (50, 2): closest ground-track point (50, 0), d2 = 2^2 / 1 = 4, ray z = 10
    assert ray_gate(CAM, d, np.array([[50.0, 2.0]]), cov, np.array([10.0]), 4.01, 0.1)[0]
    assert not ray_gate(CAM, d, np.array([[50.0, 2.0]]), cov, np.array([10.0]), 3.99, 0.1)[0]
    # behind the camera the ray does not go: the closest point is the camera's foot
    assert not ray_gate(CAM, d, np.array([[-50.0, 0.0]]), cov, np.array([20.0]), 100.0, 1.0)[0]


def _fix(t, k, p, hits, sensor="cam"):
    return Fix(t, sensor, "vehicle", k, CAM, np.asarray(p) - CAM, hits, [0.5] * len(hits))


def _shadowed_run():
    """A car seen by one camera; from 3 s to 4.5 s its rays miss it and hit 25 m beyond."""
    fixes = []
    for k in range(70):
        t = round(0.1 * k, 6)
        p = np.array([100.0, 8.0 * t, 0.0])
        if 3.0 <= t <= 4.5:
            # the ray's next crossing, 25 m farther along its ground track, at z 0 (a crest)
            u = (p - CAM)[:2] / np.hypot(*(p - CAM)[:2])
            hit = [*(p[:2] + 25.0 * u), 0.0]
        else:
            hit = list(p)
        fixes.append(_fix(t, k, p, [hit]))
    return fixes


def _run(fixes, config):
    tr = build_tracker("kalman", config=config)
    for f in fixes:
        tr.update(f)
    return tr.finish()


def test_fixes_whose_ray_passes_through_a_track_seed_no_phantom():
    fixes = _shadowed_run()
    tracks = _run(fixes, TrackerConfig())
    assert len(tracks) == 1
    assert tracks[0].points[-1].t_s == pytest.approx(6.9)
    assert max(np.hypot(*(p.p_enu[:2] - [100.0, 8.0 * p.t_s])) for p in tracks[0].points) < 3.0
    # without the ray gate the far crossings confirm a second track (the defect)
    assert len(_run(fixes, TrackerConfig(ray_gate_dz_m=None))) == 2


def test_a_second_object_behind_on_the_same_ray_is_still_tracked():
    # a second car 60 m behind the first along the ray's ground track: the ray to it passes
    # 20 m * 60 / 160 = 7.5 m above the first car, out of the 3 m height gate
    fixes = []
    for k in range(40):
        t = round(0.1 * k, 6)
        p = np.array([100.0, 8.0 * t, 0.0])
        fixes.append(_fix(t, 2 * k, p, [list(p)]))
        q = np.array([*(p[:2] * 160.0 / 100.0), 0.0])
        if t >= 1.0:
            fixes.append(_fix(t, 2 * k + 1, q, [list(q)]))
    assert len(_run(fixes, TrackerConfig())) == 2


def test_ray_gate_height_must_be_positive_or_none():
    with pytest.raises(TrackingError, match="ray_gate_dz_m"):
        TrackerConfig(ray_gate_dz_m=0.0)
    assert TrackerConfig(ray_gate_dz_m=None).ray_gate_dz_m is None


def test_a_lost_track_is_not_ended_until_its_reacquisition_window_passes():
    config = dataclasses.replace(TrackerConfig(), reacquire_s=10.0)
    tr = build_tracker("kalman", config=config)
    for k in range(30):  # 3 s seen, then nothing
        t = round(0.1 * k, 6)
        p = [100.0, 8.0 * t, 0.0]
        tr.update(_fix(t, k, p, [p]))
    far = [500.0, 500.0, 0.0]  # something else, far away, keeps time going
    for k, t in enumerate(np.arange(3.0, 16.0, 0.5)):
        tr.update(_fix(float(t), 100 + k, far, [far], sensor="other"))
        tr.flush()
        not_ended = {x.id for x in tr.tracks(include_ended=False)}
        moving = {x.id for x in tr.tracks(include_ended=False, include_lost=False)}
        # coasting up to 4 s (live), then lost until 10 s after its last fix (a new track
        # may take its id until then: Tracker._predecessor), then ended
        assert (1 in not_ended) == (t - 2.9 <= 10.0 + 1e-9), t
        assert (1 in moving) == (t - 2.9 <= 4.0 + 1e-9), t
    assert [x.id for x in tr.tracks()][:1] == [1]
