"""Geolocation at the pose of the moment in the live pipeline: oracles, no_pose, waiting.

The oracle of a posed fix is the fixed path on a site whose sensor stands at that pose
(``dataclasses.replace`` of its pan and tilt): the same camera, built independently.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from server_helpers import walk

from demtrack.core.camera.pose_series import PoseSample
from demtrack.core.site.folder import load_site
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


def posed_site(site, sensor: str, pan_deg: float, tilt_deg: float):
    """``site`` with ``sensor`` fixed at ``(pan_deg, tilt_deg)``: the oracle's camera."""
    moved = dataclasses.replace(site.sensors[sensor], pan_deg=pan_deg, tilt_deg=tilt_deg)
    return dataclasses.replace(site, sensors={**site.sensors, sensor: moved})


def pipeline(site, path, **kw):
    msgs: list[dict] = []
    p = Pipeline(site, Store(path), "kalman", msgs.extend, pose_interval_s=0.0, **kw)
    p.start()
    return p, msgs


def fix_rows(store):
    return {b["detection_id"]: b for b in store.fixes(0, 100_000)}


def rays(bodies):
    return np.array([b["origin_enu"] + b["direction_enu"] for b in bodies])


def test_a_steady_pose_equals_the_fixed_camera_at_that_pose(site, tmp_path):
    cam = site.sensors["cam1"]
    pan, tilt = cam.pan_deg + 4.0, cam.tilt_deg - 1.5
    p, msgs = pipeline(site, tmp_path / "posed.sqlite3")
    ack = p.ingest_poses("cam1", [PoseSample(k * 0.1, pan, tilt) for k in range(80)])
    assert ack["accepted"] == 80
    dets = walk(n=30, t0=0.0, dt=0.2)
    p.ingest(dets)
    posed = fix_rows(p.store)
    oracle, _ = pipeline(posed_site(site, "cam1", pan, tilt), tmp_path / "oracle.sqlite3")
    oracle.ingest(dets)
    want = fix_rows(oracle.store)
    got_b = [b for b in posed.values() if b["hits"]]
    want_b = [b for b in want.values() if b["hits"]]
    assert len(got_b) == len(want_b) > 20
    np.testing.assert_allclose(rays(got_b), rays(want_b), rtol=0, atol=1e-9)
    # and not the stored pose's: the fixed camera sees elsewhere
    fixed, _ = pipeline(site, tmp_path / "fixed.sqlite3")
    fixed.ingest(dets)
    base = [b for b in fix_rows(fixed.store).values() if b["hits"]]
    assert np.abs(rays(base)[:, 3:] - rays(got_b)[:, 3:]).max() > 0.03
    kinds = [m["type"] for m in msgs]
    assert "sensor_pose" in kinds and kinds.count("fix") == len(got_b)


def test_the_pose_between_two_samples_is_interpolated(site, tmp_path):
    cam = site.sensors["cam1"]
    p0, t0 = cam.pan_deg - 2.0, cam.tilt_deg
    p, _ = pipeline(site, tmp_path / "a.sqlite3")
    p.ingest_poses("cam1", [PoseSample(10.0, p0, t0), PoseSample(10.1, p0 + 1.0, t0 - 0.4)])
    # the frame's pose is the telemetry's at t + pose_latency_s: a quarter of the way
    rec = walk(n=1, t0=10.025 - cam.pose_latency_s)
    p.ingest(rec + walk(sensor="cam2", n=1, t0=11.0))  # cam2 moves the horizon on
    (body,) = [b for b in fix_rows(p.store).values() if b["sensor"] == "cam1"]
    oracle, _ = pipeline(posed_site(site, "cam1", p0 + 0.25, t0 - 0.1), tmp_path / "o.sqlite3")
    oracle.ingest(rec)
    (want,) = fix_rows(oracle.store).values()
    np.testing.assert_allclose(body["direction_enu"], want["direction_enu"], atol=1e-12)


def test_no_pose_near_is_stored_counted_and_never_geolocated(site, tmp_path):
    p, msgs = pipeline(site, tmp_path / "a.sqlite3")
    p.ingest_poses("cam1", [PoseSample(k * 0.1, 0.0, -10.0) for k in range(11)])  # 0..1 s
    # 1.1 s: 0.1 s after the last pose (held within the gap); 1.5 s: 0.5 s after (none)
    ack = p.ingest(walk(n=2, t0=1.1, dt=0.4) + walk(sensor="cam2", n=1, t0=3.0))
    assert ack["no_pose"] == 1
    rows = p.store._rows("SELECT detection_id, status FROM fixes ORDER BY detection_id")
    assert rows == [(1, "fix"), (2, "no_pose"), (3, "fix")]
    assert p.pose_book.n_no_pose == 1
    assert not [m for m in msgs if m["type"] == "fix" and m["fix"]["detection_id"] == 2]
    # a fixed sensor without telemetry is unchanged: cam2's fix is the fixed path's
    assert not p.pose_book.driven("cam2")


def test_a_detection_waits_for_the_pose_that_comes_after_it(site, tmp_path):
    cam = site.sensors["cam1"]
    pan = cam.pan_deg
    samples = [PoseSample(k * 0.1, pan + k * 0.5, cam.tilt_deg) for k in range(40)]
    dets = walk(n=10, t0=0.25, dt=0.3)
    # first run: each pose batch ahead of the detections it covers
    a, _ = pipeline(site, tmp_path / "a.sqlite3")
    a.ingest_poses("cam1", samples)
    a.ingest(dets)
    # second run: each detection first, the poses that cover it just after (within the lag)
    b, _ = pipeline(site, tmp_path / "b.sqlite3")
    b.ingest_poses("cam1", samples[:1])  # telemetry-driven from now on
    sent = 1
    for k, d in enumerate(dets):
        b.ingest([d])
        if k == 0:
            assert len(b.pose_book.waiting) == 1 and not fix_rows(b.store)  # stored, waiting
        upto = int((d["t"] + cam.pose_latency_s) / 0.1) + 2  # up to just after its pose
        b.ingest_poses("cam1", samples[sent:upto])
        sent = upto
        assert sorted(fix_rows(b.store)) == list(range(1, k + 2))  # settled at once
    b.ingest_poses("cam1", samples[sent:])
    got, want = fix_rows(b.store), fix_rows(a.store)
    assert sorted(got) == sorted(want) == list(range(1, 11))
    for k in want:
        assert got[k]["direction_enu"] == want[k]["direction_enu"]  # bit for bit
    assert a.store.tracks() == b.store.tracks()


def test_a_waiting_detection_is_decided_once_the_reorder_horizon_passes(site, tmp_path):
    p, _ = pipeline(site, tmp_path / "a.sqlite3", reorder_lag_s=0.5)
    p.ingest_poses("cam1", [PoseSample(0.0, 0.0, -10.0), PoseSample(1.0, 0.5, -10.0)])
    p.ingest(walk(n=1, t0=1.1))  # held pose within the gap, not settled: waits
    assert len(p.pose_book.waiting) == 1
    p.ingest(walk(sensor="cam2", n=1, t0=1.5))  # horizon 1.0: still waits
    assert len(p.pose_book.waiting) == 1
    p.ingest(walk(sensor="cam2", n=1, t0=1.7))  # horizon 1.2: decided with what there is
    assert not p.pose_book.waiting
    assert p.store._rows("SELECT status FROM fixes WHERE detection_id = 1") == [("fix",)]


def test_restart_reloads_the_poses_and_the_waiting_detections(site, tmp_path):
    cam = site.sensors["cam1"]
    samples = [PoseSample(k * 0.1, cam.pan_deg + k * 0.2, cam.tilt_deg) for k in range(70)]
    dets = walk(n=20, t0=0.25, dt=0.3)
    whole, _ = pipeline(site, tmp_path / "whole.sqlite3")
    cut = tmp_path / "cut.sqlite3"
    first, _ = pipeline(site, cut)
    for run, stop in ((whole, None), (first, 8)):
        for k in range(0, 20, 4):
            if stop is not None and k >= stop:
                break
            run.ingest_poses("cam1", samples[k * 3 : k * 3 + 12])
            run.ingest(dets[k : k + 4])
    assert first.pose_book.waiting  # detections without their pose yet at the "crash"
    first.store.close()
    second, _ = pipeline(site, cut)  # start-up: poses reloaded before the unprocessed
    assert second.pose_book.last_t == first.pose_book.last_t
    assert sorted(second.pose_book.waiting) == sorted(first.pose_book.waiting)
    for k in range(8, 20, 4):
        second.ingest_poses("cam1", samples[k * 3 : k * 3 + 12])
        second.ingest(dets[k : k + 4])
    got, want = fix_rows(second.store), fix_rows(whole.store)
    assert sorted(got) == sorted(want)
    assert all(got[k] == want[k] for k in want)
    assert second.store.tracks() == whole.store.tracks()
    assert second.store.poses("cam1") == whole.store.poses("cam1")


def test_inline_poses_of_detection_records_are_stored_and_used(site, tmp_path):
    cam = site.sensors["cam1"]
    pan, tilt = cam.pan_deg + 3.0, cam.tilt_deg
    recs = []
    for k in range(10):
        for r in walk(n=1, t0=k * 0.1, u0=500.0 + 4 * k) + walk(n=1, t0=k * 0.1, u0=700.0 + k):
            recs.append({**r, "pan_deg": pan, "tilt_deg": tilt, "hfov_deg": None})
    recs = [{k: v for k, v in r.items() if v is not None} for r in recs]
    p, _ = pipeline(site, tmp_path / "a.sqlite3")
    ack = p.ingest(recs + walk(sensor="cam2", n=1, t0=2.0))
    assert ack["poses"] == 10 and "pose_skipped" not in ack  # one per frame, not per box
    assert [b["t_s"] for b in p.store.poses("cam1")] == [r["t"] for r in recs[::2]]
    oracle, _ = pipeline(posed_site(site, "cam1", pan, tilt), tmp_path / "o.sqlite3")
    oracle.ingest([{k: v for k, v in r.items() if "_deg" not in k} for r in recs])
    got = [b for b in fix_rows(p.store).values() if b["sensor"] == "cam1" and b["hits"]]
    want = [b for b in fix_rows(oracle.store).values() if b["hits"]]
    np.testing.assert_allclose(rays(got), rays(want), atol=1e-9)
