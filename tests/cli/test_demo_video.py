"""``demtrack demo --video`` / ``serve --replay ... --video``: the replay from pixels.

End to end on real uvicorn: the sample-video renderer makes cam3's video of a short span
of the vehicle run (into a test folder, then reused), the video replay decodes and
detects it on the replay's clock, and the console gets tracks from those detections (one
of them a vehicle on the scenario's true path) and the frames (``/api/frames``,
``frame.jpg``). The command line refuses, in one line, what video cannot play.
"""

from __future__ import annotations

import socket
import threading
import time

import httpx2 as httpx
import numpy as np
import pytest

from demtrack.cli import main
from demtrack.commands.serve import VIDEO_NAMES, live_overrides, scenario_source
from demtrack.core.site.folder import load_site
from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS
from demtrack.samplesite.video_cache import VIDEO_SCENARIOS, SampleVideos, video_path
from demtrack.server.app import create_app

pytestmark = pytest.mark.timeout(900)
TOKEN = "demo-video-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
START_S = 1_796_135_400.0  # 2026-12-01T14:30:00Z
LEAD_IN_S, SPAN_S = 3.0, 7.0


def test_video_flags_refuse_what_video_cannot_play(capsys, tmp_path):
    assert main(["serve", "--site", str(tmp_path), "--video", "--replay", "loitering"]) == 2
    assert "--video cannot play 'loitering'" in capsys.readouterr().err
    assert main(["serve", "--site", str(tmp_path), "--video"]) == 2
    assert "give --replay SCENARIO too" in capsys.readouterr().err
    assert main(["demo", "--site", str(tmp_path), "--video", "--replay", "active-handoff"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "vehicle-run, pedestrians, passing-vehicles" in err
    assert VIDEO_NAMES == VIDEO_SCENARIOS  # the parser's copy of the renderer's list


def test_video_overrides_and_source():
    import argparse

    args = argparse.Namespace(replay=None, video=True, speed=2.0, viser_port=0, host="h",
                              start="2026-12-01T14:30:00Z")  # fmt: skip
    live = live_overrides(args, ["loitering"])
    assert live["replay"] == ["vehicle-run", "pedestrians"] and live["replay_video"] is True
    assert isinstance(scenario_source(live), SampleVideos)
    assert scenario_source({**live, "replay_video": False}) is SAMPLE_SCENARIOS


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def videos(sample_site_dir, tmp_path_factory):
    """cam3's short video of the vehicle run (the car comes into view at t = 0)."""
    src = SampleVideos(
        folder=tmp_path_factory.mktemp("videos"), lead_in_s=LEAD_IN_S, span_s=SPAN_S,
        sensors=("cam3",),
    )  # fmt: skip
    site = load_site(sample_site_dir)
    clip = src.video(site, "vehicle-run", "cam3")
    assert clip.path == video_path(src.folder, "vehicle-run", "cam3")
    assert (clip.t_from_s, clip.t_to_s) == pytest.approx((-LEAD_IN_S, SPAN_S - LEAD_IN_S))
    mtime = clip.path.stat().st_mtime_ns
    assert src.video(site, "vehicle-run", "cam3") == clip  # reused, not rendered again
    assert clip.path.stat().st_mtime_ns == mtime and list(src.rendered_s) == ["vehicle-run-cam3"]
    assert src.video(site, "vehicle-run", "cam1") is None
    return src


def test_demo_from_video_tracks_the_car_and_serves_frames(sample_site_dir, tmp_path, videos):
    import uvicorn

    app = create_app(
        scenarios=videos, site=sample_site_dir, db_path=tmp_path / "demo.sqlite3", token=TOKEN,
        replay=["vehicle-run"], replay_video=True, replay_loop=False, replay_start_s=START_S,
        heads="off",
    )  # fmt: skip
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while not server.started:
            assert time.monotonic() < deadline and thread.is_alive()
            time.sleep(0.1)
        replay = app.state.replay
        with httpx.Client(base_url=url, headers=AUTH, timeout=30) as c:
            seen_frames = set()
            deadline = time.monotonic() + 600
            while replay.running and time.monotonic() < deadline:
                idx = c.get("/api/frames").json()["frames"]
                if "cam3" in idx:
                    seen_frames.add(idx["cam3"]["etag"])
                time.sleep(0.3)
            assert replay.error is None, replay.error
            assert not replay.running
            time.sleep(2.0)  # the reorder lag: the last fixes reach the tracker
            tracks = c.get("/api/tracks").json()["tracks"]
            jpg = c.get("/api/sensors/cam3/frame.jpg")
            dets = c.get("/api/detections", params={"limit": 10000}).json()
    finally:
        server.should_exit = True
        thread.join(30)
    stats = replay.stats()
    n_frames = round(SPAN_S * 10) + 1
    assert stats["frames"] == {"cam3": n_frames}  # every frame detected, none skipped
    assert len(seen_frames) >= 3 and stats["shown"] >= 3
    assert jpg.status_code == 200 and jpg.headers["content-type"] == "image/jpeg"
    t_frame = float(jpg.headers["x-frame-time-s"])
    assert START_S <= t_frame <= START_S + SPAN_S + 1e-6
    # Detections are the detector's (its local ids), on the replay clock, from cam3 only.
    assert dets and {d["sensor"] for d in dets} == {"cam3"}
    assert all(START_S <= d["t"] <= START_S + SPAN_S + 1e-6 for d in dets)
    # A vehicle track on the car's true path (the replay's t0 is the clip's first frame).
    truth = next(
        tr for tr in SAMPLE_SCENARIOS.make(load_site(sample_site_dir), "vehicle-run", seed=0).truths
        if tr.cls == "vehicle"
    )  # fmt: skip
    best = np.inf
    for tr in tracks:
        pts = tr["points"]
        if len(pts) < 10:
            continue
        tau = np.array([p["t_s"] for p in pts]) - START_S - LEAD_IN_S
        err = np.hypot(*(np.array([[p["e_m"], p["n_m"]] for p in pts]) - truth.at(tau)[:, :2]).T)
        err = err[np.isfinite(err)]  # NaN: before the car starts or after the truth ends
        if len(err) >= 10:
            best = min(best, float(np.median(err)))
    assert best < 5.0, f"no track within 5 m of the car (best median error {best:.1f} m)"
