"""Replays of moving cameras: a scenario's poses go out ahead of the detections they cover."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from demtrack.core.camera.pose_series import PoseSample, PoseSeries
from demtrack.core.site.folder import load_site
from demtrack.core.tracking.types import Detection
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.ingest.offline_replay import replay_detections
from demtrack.server.replay import Replay, loop_frames, merge_frames, scenario_frames

pytestmark = pytest.mark.timeout(600)

BOX = (10.0, 10.0, 20.0, 40.0)


def series(times, pan0=0.0):
    return PoseSeries.from_samples([PoseSample(t, pan0 + t, -5.0) for t in times])


def test_frames_carry_each_sensors_poses_at_their_own_times():
    dets = [Detection(0.1, "cam1", BOX, "human"), Detection(0.2, "cam2", BOX, "human")]
    frames = scenario_frames(dets, {"cam1": series([0.05, 0.1, 0.15])})
    got = [(f.t_s, f.sensor, len(f.records), [p["t"] for p in f.poses]) for f in frames]
    assert got == [
        (0.05, "cam1", 0, [0.05]),
        (0.1, "cam1", 1, [0.1]),
        (0.15, "cam1", 0, [0.15]),
        (0.2, "cam2", 1, []),
    ]
    assert frames[1].poses[0] == {"t": 0.1, "pan_deg": 0.1, "tilt_deg": -5.0}
    # a loop shifts the poses' times with the frame's; merging joins them too
    looped = list(loop_frames(frames, 100.0, loop=False))
    assert [p["t"] for f in looped for p in f.poses] == [100.05, 100.1, 100.15]
    (joined,) = merge_frames([looped[1:2], looped[1:2]])
    assert len(joined.poses) == 2 and len(joined.records) == 2
    assert scenario_frames(dets) == scenario_frames(dets, None)  # no poses: as before


def test_the_replay_posts_a_batchs_poses_before_its_detections():
    dets = [Detection(t, "cam1", BOX, "human") for t in (0.1, 0.2, 0.3)]
    frames = scenario_frames(dets, {"cam1": series([0.0, 0.1, 0.2, 0.3, 0.4])})
    log: list[tuple] = []
    r = Replay(
        lambda: frames,
        lambda recs: log.append(("dets", [x["t"] for x in recs])) or {"accepted": len(recs)},
        send_poses=lambda s, recs: log.append(("poses", s, [x["t"] for x in recs])),
        speed=1000.0,
        max_coalesce=2,
    )
    r._play(frames)
    poses_sent = [t for e in log if e[0] == "poses" for t in e[2]]
    assert poses_sent == [0.0, 0.1, 0.2, 0.3, 0.4]  # every pose, in time order
    for k, e in enumerate(log):
        if e[0] == "dets":  # every detection's pose went out before it
            assert max(e[1]) <= max(t for x in log[:k] if x[0] == "poses" for t in x[2])
    assert r.n_records == 3 and r.n_accepted == 3
    # without send_poses the poses are dropped and the detections go as before
    plain: list = []
    Replay(lambda: frames, lambda recs: plain.append(recs) or {}, speed=1000.0)._play(frames)
    assert sum(len(b) for b in plain) == 3


def test_an_offline_replay_with_a_steady_pose_tracks_as_the_fixed_cameras(sample_site_dir):
    """Oracle: poses that hold every camera at its surveyed pan and tilt give the tracks of
    the fixed cameras (the posed path builds the same cameras)."""
    site = load_site(sample_site_dir)
    dets = [d for d in make_scenario(site, "vehicle-run").detections if d.t_s < 12.0]
    times = np.round(np.arange(0.0, 12.2, 0.05), 6)
    steady = {
        sid: PoseSeries.from_samples([PoseSample(float(t), s.pan_deg, s.tilt_deg) for t in times])
        for sid, s in site.sensors.items()
    }
    fixed = replay_detections(site, dets)
    posed = replay_detections(site, dets, poses=steady)
    assert len(fixed.tracks) == len(posed.tracks) > 0
    for a, b in zip(fixed.tracks, posed.tracks, strict=True):
        assert [p.t_s for p in a.points] == [p.t_s for p in b.points]
        pa = np.array([p.p_enu for p in a.points])
        pb = np.array([p.p_enu for p in b.points])
        np.testing.assert_allclose(pa, pb, atol=1e-6)
    # and a scenario object with poses plays them (the live replay reads .poses)
    sc = SimpleNamespace(detections=dets, truths=[], poses=steady)
    frames = scenario_frames(sc.detections, getattr(sc, "poses", None))
    assert sum(len(f.poses) for f in frames) == len(times) * len(site.sensors)


def _horizontal_error_m(tracks, truths) -> np.ndarray:
    """Each track point's horizontal distance to the nearest target's true position then."""
    errs = []
    for tr in tracks:
        for p in tr.points:
            best = np.inf
            for truth in truths:
                if truth.t_s[0] <= p.t_s <= truth.t_s[-1]:
                    xy = [np.interp(p.t_s, truth.t_s, truth.p_enu[:, k]) for k in (0, 1)]
                    best = min(best, float(np.hypot(*(np.asarray(p.p_enu[:2]) - xy))))
            errs.append(best)
    return np.array(errs)


def test_an_active_scenarios_replay_geolocates_at_the_heads_poses(sample_site_dir):
    """Oracle: the scenario's truth. Replayed with its heads' telemetry, the server's
    tracks lie on the target; with the telemetry left out (the fixed poses), they do not."""
    site = load_site(sample_site_dir)
    sc = make_scenario(site, "active-handoff")
    assert sc.poses, "the active scenario carries its heads' poses"
    end = min(float(d.t_s) for d in sc.detections) + 40.0
    dets = [d for d in sc.detections if d.t_s < end]
    posed = replay_detections(site, dets, poses=sc.poses)
    fixed = replay_detections(site, dets)
    err_posed = _horizontal_error_m(posed.tracks, sc.truths)
    assert len(err_posed) > 50
    assert np.median(err_posed) < 2.0, np.median(err_posed)
    err_fixed = _horizontal_error_m(fixed.tracks, sc.truths)
    assert len(err_fixed) == 0 or np.median(err_fixed) > 2 * np.median(err_posed)
