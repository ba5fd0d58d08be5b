"""The tracker's fix in the live path is exactly the one the start-up replay rebuilds."""

from __future__ import annotations

import json

import numpy as np
import pytest
from server_helpers import vehicle_run_pipeline

from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.ingest.fix_codec import fix_from_body
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


def test_live_fixes_equal_the_stored_bodies_fixes(sample_site_dir, tmp_path):
    site, p, records = vehicle_run_pipeline(sample_site_dir, tmp_path, until_s=6.0)
    validated, _ = p._validate(records)
    pending = list(enumerate(validated, start=1))
    from demtrack.core.geolocation.fix_builder import build_fixes

    fixes, _ = build_fixes(site, validated)
    bodies, unfilled = p._fix_bodies(pending, fixes)  # geodetic fields unfilled: not read back
    live = p._queued_fixes
    # the geodetic work holds every hit and road point of the bodies once, at its point
    want = [h for b in bodies if b for h in b["hits"] + ([b["road_hit"]] if b["road_hit"] else [])]
    assert any(b["road_hit"] for b in bodies if b)
    work = [
        (row, d)
        for points, dicts in unfilled
        for row, d in zip(points.tolist(), dicts, strict=True)
    ]
    assert sorted(map(id, want)) == sorted(id(d) for _, d in work)
    assert all(row == [d["e_m"], d["n_m"], d["u_m"]] for row, d in work)
    n = 0
    for body in bodies:
        if body is None:
            continue
        a = live[body["detection_id"]]
        b = fix_from_body(json.loads(json.dumps(body)))  # as the replay reads it back
        for name in ("t_s", "sensor", "cls", "detection_index", "score"):
            assert getattr(a, name) == getattr(b, name)
        assert a.hit_cov_en_m2 is not None  # the tracker gets the hits' covariances
        for name in (
            "origin_enu",
            "direction_enu",
            "hits_enu",
            "hit_sigma_m",
            "road_hit_enu",
            "hit_cov_en_m2",
        ):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None) == (y is None)
            if x is not None:
                assert x.dtype == y.dtype and x.shape == y.shape
                assert x.tobytes() == y.tobytes()  # bit for bit
                assert not x.flags.writeable
        n += 1
    assert n > 50
    # the fix is the one the offline builder made, covariances included
    by_index = {f.detection_index: f for f in fixes}
    for det_id, fix in live.items():
        np.testing.assert_array_equal(fix.hit_cov_en_m2, by_index[det_id - 1].hit_cov_en_m2)
    # a body stored before covariances were kept gives a fix without them
    old = json.loads(json.dumps(next(b for b in bodies if b)))
    for h in old["hits"]:
        del h["cov_en_m2"]
    assert fix_from_body(old).hit_cov_en_m2 is None
    # a malformed body still goes through the checked constructor
    bad = dict(bodies[0] or next(b for b in bodies if b), origin_enu=[0.0, float("nan"), 0.0])
    with pytest.raises(ValueError):
        fix_from_body(bad)
    assert np.isfinite(fix_from_body(json.loads(json.dumps(next(b for b in bodies if b)))).t_s)


def test_live_tracks_equal_the_offline_tracker_on_the_same_detections(sample_site_dir, tmp_path):
    """Oracle: the server's tracker, fed batch by batch through ingest, store and reorder
    buffer, makes the tracks ``run_tracker`` makes from ``build_fixes`` offline (what
    ``demtrack track`` does) - hit covariances included, so the live tracks are as good."""
    from demtrack.core.geolocation.fix_builder import build_fixes
    from demtrack.core.tracking import build_tracker

    site = load_site(sample_site_dir)
    dets = [d for d in make_scenario(site, "passing-vehicles").detections if d.t_s < 25.0]
    dets.sort(key=lambda d: (d.t_s, d.sensor))
    records = [{"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls} for d in dets]
    p = Pipeline(site, Store(tmp_path / "o.sqlite3"), "kalman", lambda _m: None)
    p.start()
    for k in range(0, len(records), 37):  # odd batch sizes: batches split frames
        ack = p.ingest(records[k : k + 37])
        assert ack["accepted"] == len(records[k : k + 37])
    # offline: the same fixes in the same (time, sensor, detection) order, minus those the
    # server still holds in its reorder buffer
    fixes, _ = build_fixes(site, dets)
    order = sorted(fixes, key=lambda f: (f.t_s, f.sensor, f.detection_index))
    offline = build_tracker("kalman", roads=site.roads)
    for f in order[: len(order) - p.n_buffered]:
        offline.update(f, index=f.detection_index + 1)  # detection ids count from 1
    live_tracks, want = p.tracker.tracks(), offline.tracks()
    assert len(want) >= 2
    assert [t.id for t in live_tracks] == [t.id for t in want]
    for a, b in zip(live_tracks, want, strict=True):
        assert [q.fix_indices for q in a.points] == [q.fix_indices for q in b.points]
        # the stored direction is normalised once more: equal to rounding
        np.testing.assert_allclose(a.p_enu, b.p_enu, rtol=0, atol=1e-9)
