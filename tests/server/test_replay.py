"""Live replay: frames, loops, pacing, stopping, and tracks that follow the scenario truth."""

from __future__ import annotations

import itertools
import json
import shutil
import threading
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app

from demtrack.core.errors import SiteError
from demtrack.core.site.folder import load_site
from demtrack.core.tracking.types import Detection
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.replay import (
    Replay,
    ReplayFrame,
    loop_frames,
    merge_frames,
    scenario_frames,
    start_time_after,
)

pytestmark = pytest.mark.timeout(300)


def dets() -> list[Detection]:
    box = (10.0, 10.0, 20.0, 40.0)
    return [
        Detection(0.0, "cam1", box, "human", 0.9),
        Detection(0.0, "cam1", box, "vehicle"),
        Detection(0.0, "cam2", box, "human"),
        Detection(0.1, "cam2", box, "human", local_id="a"),
        Detection(0.3, "cam1", box, "human"),
    ]


def test_frames_are_one_batch_per_camera_per_frame_in_time_order():
    frames = scenario_frames(dets())
    assert [(f.t_s, f.sensor, len(f.records)) for f in frames] == [
        (0.0, "cam1", 2),
        (0.0, "cam2", 1),
        (0.1, "cam2", 1),
        (0.3, "cam1", 1),
    ]
    box = [10.0, 10.0, 20.0, 40.0]
    assert frames[0].records == (
        {"t": 0.0, "sensor": "cam1", "bbox": box, "class": "human", "score": 0.9},
        {"t": 0.0, "sensor": "cam1", "bbox": box, "class": "vehicle"},
    )
    assert frames[2].records[0]["local_id"] == "a"


def test_loops_shift_time_so_every_sensor_keeps_moving_forward():
    frames = scenario_frames(dets())
    out = list(itertools.islice(loop_frames(frames, 100.0, gap_s=5.0), 12))
    # last frame 0.3 s + gap 5 s: loop k starts at 100 + 5.3 k
    assert [f.t_s for f in out[::4]] == [100.0, 105.3, 110.6]
    for f in out:
        assert all(r["t"] == f.t_s and r["sensor"] == f.sensor for r in f.records)
    for sensor in ("cam1", "cam2"):
        t = [f.t_s for f in out if f.sensor == sensor]
        assert all(b > a for a, b in itertools.pairwise(t))
    assert len(list(loop_frames(frames, 0.0, loop=False))) == len(frames)


def test_merge_joins_same_frame_and_keeps_order():
    a = [ReplayFrame(0.0, "cam1", ({"k": 1},)), ReplayFrame(0.2, "cam1", ({"k": 2},))]
    b = [ReplayFrame(0.0, "cam1", ({"k": 3},)), ReplayFrame(0.1, "cam2", ({"k": 4},))]
    out = list(merge_frames([a, b]))
    assert [(f.t_s, f.sensor, [r["k"] for r in f.records]) for f in out] == [
        (0.0, "cam1", [1, 3]),
        (0.1, "cam2", [4]),
        (0.2, "cam1", [2]),
    ]


def test_start_time_is_after_what_is_stored():
    assert start_time_after({}) == 0.0
    assert start_time_after({"cam1": 12.2, "cam2": 30.01}, gap_s=5.0) == 36.0


def test_replay_sends_everything_in_order_and_stops():
    frames = [ReplayFrame(0.01 * k, "cam1", ({"t": 0.01 * k},)) for k in range(200)]
    got: list[list[dict]] = []
    replay = Replay(lambda: frames, lambda recs: got.append(recs) or {"accepted": len(recs)})
    replay.speed = 1000.0
    replay.start()
    for _ in range(200):
        if not replay.running:
            break
        time.sleep(0.05)
    assert replay.stop() and replay.error is None
    sent = [r["t"] for batch in got for r in batch]
    assert sent == [f.records[0]["t"] for f in frames]
    assert replay.n_frames == 200 and replay.n_records == 200 == replay.n_accepted
    assert replay.n_batches == len(got) <= 200


def test_replay_batches_the_frames_due_within_its_interval():
    # 2 s of frames every 10 ms at 1x, sent at most every 0.25 s: the frames that fall due
    # in between wait and go together, none before it is due, all in order.
    frames = [ReplayFrame(0.01 * k, "cam1", ({"t": 0.01 * k},)) for k in range(200)]
    sends: list[tuple[float, list[dict]]] = []
    replay = Replay(
        lambda: frames,
        lambda recs: sends.append((time.monotonic(), recs)) or {"accepted": len(recs)},
        min_interval_s=0.25,
    )
    t_start = time.monotonic()
    replay.start()
    wait_done(replay, 30.0)
    assert replay.stop() and replay.error is None
    assert [r["t"] for _, recs in sends for r in recs] == [f.t_s for f in frames]
    times = [t for t, _ in sends]
    # (the send's own clock reading can trail the replay's by a thread switch: 50 ms slack)
    assert all(b - a >= 0.25 - 0.05 for a, b in itertools.pairwise(times))
    assert all(t - t_start >= recs[-1]["t"] for t, recs in sends)  # nothing sent early
    assert 2 <= replay.n_batches <= 9 and replay.n_frames == 200


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_replay_batch_interval_must_be_a_number_of_seconds(bad):
    with pytest.raises(ValueError, match="batch interval"):
        Replay(list, print, min_interval_s=bad)


def test_replay_paces_at_speed_and_stops_while_waiting():
    endless = (ReplayFrame(float(k), "cam1", ({"t": float(k)},)) for k in itertools.count())
    got: list[list[dict]] = []
    sent = threading.Event()

    def send(recs):
        got.append(recs)
        sent.set()
        return {"accepted": 1}

    # One replay second is 100 wall seconds: after the first frame it sleeps.
    replay = Replay(lambda: endless, send, speed=0.01).start()
    assert sent.wait(30)
    assert replay.stop(timeout_s=10.0)  # stop wakes it
    assert not replay.running and replay.error is None
    assert [r["t"] for b in got for r in b] == [0.0]


def test_replay_reports_a_failing_ingest_and_ends():
    def send(recs):
        raise RuntimeError("store closed")

    replay = Replay(lambda: [ReplayFrame(0.0, "cam1", ({},))], send).start()
    assert replay.stop()
    assert isinstance(replay.error, RuntimeError) and replay.n_frames == 0


def test_speed_must_be_positive():
    with pytest.raises(ValueError, match="speed"):
        Replay(list, print, speed=0.0)


def wait_done(replay: Replay, timeout_s: float = 240.0) -> None:
    deadline = time.monotonic() + timeout_s
    while replay.running and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not replay.running, "replay did not finish"
    assert replay.error is None


def test_replayed_tracks_follow_the_scenario_truth(sample_site_dir, tmp_path, store_kw):
    scenario = make_scenario(load_site(sample_site_dir), "passing-vehicles")
    truth = scenario.truths
    app = make_app(
        sample_site_dir,
        tmp_path,
        replay=["passing-vehicles"],
        replay_speed=200.0,
        replay_loop=False,
        **store_kw,
    )
    with TestClient(app) as client:
        replay = app.state.replay
        assert replay.min_interval_s == app.state.settings.replay_batch_s == 0.1
        wait_done(replay)
        assert replay.n_records == len(scenario.detections) == replay.n_accepted
        tracks = client.get("/api/tracks", headers=AUTH).json()["tracks"]
        status = client.get("/api/status", headers=AUTH).json()["counts"]
    assert status["detections"] == replay.n_records
    assert replay.t_s == scenario.detections[-1].t_s  # a fresh store: scenario time itself
    # Every true car is followed by a track: at the track's times the truth (linearly
    # interpolated) is within a few metres of its points, for a good part of the run.
    for tr in truth:
        best = 0.0
        for track in tracks:
            pts = track["points"]
            t = np.array([p["t_s"] for p in pts])
            inside = (t >= tr.t_s[0]) & (t <= tr.t_s[-1])
            if inside.sum() < 20:
                continue
            e = np.array([p["e_m"] for p in pts])[inside]
            n = np.array([p["n_m"] for p in pts])[inside]
            te, tn = (np.interp(t[inside], tr.t_s, tr.p_enu[:, k]) for k in (0, 1))
            err = np.hypot(e - te, n - tn)
            if np.median(err) < 3.0:
                best = max(best, float(np.ptp(t[inside])))
        assert best > 5.0, f"no track follows target {tr.target_id}"
    assert not replay.running


def test_a_restart_replays_after_the_stored_times(sample_site_dir, tmp_path, store_kw):
    kw = {"replay": ["passing-vehicles"], "replay_speed": 500.0, "replay_loop": False, **store_kw}
    app = make_app(sample_site_dir, tmp_path, **kw)
    with TestClient(app):
        wait_done(app.state.replay)
        first_end = app.state.replay.t_s
    app = make_app(sample_site_dir, tmp_path, **kw)
    with TestClient(app) as client:
        replay = app.state.replay
        deadline = time.monotonic() + 120
        while replay.n_frames < 30 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert replay.stop()
        assert replay.n_frames >= 30 and replay.n_accepted == replay.n_records
        body = client.get("/api/detections?after_id=0&limit=10000", headers=AUTH).json()
    second = [d["t"] for d in body if d["t"] > first_end]
    assert second and min(second) >= first_end + 5.0


def test_replay_needs_a_generated_sample_site(sample_site_dir, tmp_path):
    site = tmp_path / "site"
    shutil.copytree(sample_site_dir, site, ignore=shutil.ignore_patterns("*.npy", "*.sqlite3*"))
    doc = json.loads((site / "site.json").read_text())
    doc.pop("generator")
    (site / "site.json").write_text(json.dumps(doc))
    with pytest.raises(SiteError, match="not a generated sample site"):
        make_app(site, tmp_path, replay=["vehicle-run"])
    make_app(site, tmp_path)  # without a replay the site is fine
