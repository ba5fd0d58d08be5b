"""Group commit: batches that arrive together are committed and processed as one group,
with the results of handling them one by one in the same order."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.replay import scenario_frames
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


def _wait(cond, timeout_s=30.0):
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.001)


def test_camera_batches_posted_at_once_commit_as_one_and_track_as_one_by_one(
    sample_site_dir, tmp_path
):
    site = load_site(sample_site_dir)
    frames = scenario_frames(make_scenario(site, "passing-vehicles").detections)
    frames = [f for f in frames if f.t_s < 15.0]
    by_time: dict[float, list] = {}
    for f in frames:
        by_time.setdefault(f.t_s, []).append(f)
    grouped = Pipeline(site, Store(tmp_path / "g.sqlite3"), "kalman", lambda _m: None)
    grouped.start()
    acks: dict[int, dict] = {}
    n_groups = 0
    for t in sorted(by_time):
        batch = by_time[t]
        # Hold the lock while every camera of the frame posts: the batches queue up and
        # the first to get the lock handles all of them.
        with grouped._lock:
            threads = [
                threading.Thread(
                    target=lambda k=k, f=f: acks.__setitem__(k, grouped.ingest(f.records))
                )
                for k, f in ((frames.index(f), f) for f in batch)
            ]
            for th in threads:
                th.start()
            n_posts = len(threads)
            _wait(lambda n=n_posts: len(grouped._waiting) == n)
        for th in threads:
            th.join(60)
        n_groups += 1
    assert len(acks) == len(frames)
    assert grouped.n_commits == n_groups < grouped.n_batches == len(frames)
    # The reference: the same batches one by one, in the order the group committed them.
    order = sorted(acks, key=lambda k: acks[k]["batch_id"])
    single = Pipeline(site, Store(tmp_path / "s.sqlite3"), "kalman", lambda _m: None)
    single.start()
    for k in order:
        ack = single.ingest(frames[k].records)
        assert ack["detection_ids"] == acks[k]["detection_ids"]
        assert ack["accepted"] == acks[k]["accepted"] == len(frames[k].records)
    assert single.n_commits == len(frames)
    a, b = grouped.tracker.tracks(), single.tracker.tracks()
    assert len(a) >= 2 and [t.id for t in a] == [t.id for t in b]
    for ta, tb in zip(a, b, strict=True):
        assert [p.fix_indices for p in ta.points] == [p.fix_indices for p in tb.points]
        np.testing.assert_array_equal(ta.p_enu, tb.p_enu)
    assert grouped.store.counts()["detections"] == single.store.counts()["detections"]
    assert grouped.store.fixes(0, 10_000) == single.store.fixes(0, 10_000)


def test_a_repeated_key_inside_one_group_is_a_duplicate(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    frame = scenario_frames(make_scenario(site, "passing-vehicles").detections)[0]
    p = Pipeline(site, Store(tmp_path / "d.sqlite3"), "kalman", lambda _m: None)
    p.start()
    out: list[dict] = []
    with p._lock:
        threads = [
            threading.Thread(target=lambda: out.append(p.ingest(frame.records, batch_key="k1")))
            for _ in range(2)
        ]
        for th in threads:
            th.start()
        _wait(lambda: len(p._waiting) == 2)
    for th in threads:
        th.join(60)
    assert sorted(a["duplicate"] for a in out) == [False, True]
    assert out[0]["detection_ids"] == out[1]["detection_ids"]
    assert p.store.counts()["detections"] == len(frame.records)
    assert p.n_commits == 1


def test_a_batch_the_database_refuses_fails_alone_in_its_group(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    frames = scenario_frames(make_scenario(site, "passing-vehicles").detections)
    p = Pipeline(site, Store(tmp_path / "f.sqlite3"), "kalman", lambda _m: None)
    p.start()
    before = dict(p._last_t)
    p.store._w.execute(
        "CREATE TRIGGER no_more BEFORE INSERT ON detections WHEN NEW.sensor = 'cam2'"
        " BEGIN SELECT RAISE(ABORT, 'disk says no'); END"
    )
    errors: list[BaseException] = []

    def post(f):
        try:
            p.ingest(f.records)
        except Exception as exc:  # noqa: BLE001 - the test collects it
            errors.append(exc)

    # a good batch and one the database refuses, in one group: the good one is kept and
    # acknowledged (issue 26: one client's bad batch never fails another's; before, the
    # shared transaction failed both)
    two = [next(f for f in frames if f.sensor == s) for s in ("cam1", "cam2")]
    with p._lock:
        threads = [threading.Thread(target=post, args=(f,)) for f in two]
        for th in threads:
            th.start()
        _wait(lambda: len(p._waiting) == 2)
    for th in threads:
        th.join(60)
    assert len(errors) == 1 and "disk says no" in str(errors[0])
    good = two[0]
    assert p.store.counts()["detections"] == len(good.records)
    assert p.store.counts()["batches"] == 1
    assert {d.sensor for _, d in p.store.detections(0, 1000)} == {"cam1"}
    # the refused batch's time never counted
    assert p._last_t == {**before, "cam1": max(r["t"] for r in good.records)}
