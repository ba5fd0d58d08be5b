"""``demtrack watch --frames``: frames reach the server's frame book, detections are untouched.

Real uvicorn, a real clip (the site's still with bodies moving over the DEM, from the
video tests' synthesiser). Oracles: the detections stored are exactly those a JSON Lines
run of the same watch writes; the served frame is of the clip (its time inside the
clip's span, its pixels the clip's still); a poster whose server cannot be reached
loses frames only, says so once, and never blocks.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import httpx2 as httpx
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "core" / "video"))
sys.path.insert(0, str(Path(__file__).parents[1] / "cli"))
from synth import Body, site_clip  # noqa: E402
from test_watch_server import AUTH, TOKEN, free_port, start_server  # noqa: E402

from demtrack.commands.watch_frames import FramePoster  # noqa: E402
from demtrack.core.io.times import parse_iso_time  # noqa: E402
from demtrack.core.site.folder import load_site  # noqa: E402

pytestmark = pytest.mark.timeout(600)
CLIP_START = parse_iso_time("2026-11-18T09:46:40Z", "t")


def test_watch_posts_frames_beside_the_same_detections(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    bodies = [
        Body("vehicle", (900, 500), (-6.0, 2.0), (1.8, 4.5, 1.5), grey=200, frames=(4, 10**9))
    ]
    clip = site_clip(tmp_path / "cam1.mp4", site, "cam1", bodies, n_frames=100)
    watch = [sys.executable, "-m", "demtrack.cli", "watch", "--site", str(sample_site_dir)]
    watch += ["--sensor", "cam1", "--source", str(clip.path), "--quiet"]
    ref = tmp_path / "ref.jsonl"
    subprocess.run([*watch, "-o", str(ref)], check=True, capture_output=True, timeout=300)
    want = sorted((r["t"], tuple(r["bbox"]), r["class"]) for r in map(json.loads, ref.open()))
    assert want
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    server = start_server(sample_site_dir, tmp_path / "db.sqlite3", port)
    try:
        run = subprocess.run(
            [*watch, "--server", url, "--token", TOKEN, "--frames", "--frame-rate", "5"],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            got = c.get("/api/detections", params={"limit": 10000}).json()
            frame = c.get("/api/sensors/cam1/frame.jpg")
            other = c.get("/api/sensors/cam2/frame.jpg")
    finally:
        server.kill()
        server.wait(10)
    assert sorted((d["t"], tuple(d["bbox"]), d["class"]) for d in got) == want
    m = __import__("re").search(r"(\d+) frames to", run.stdout)
    # 100 frames at 25 fps are 4 s of video: at 5 Hz about 20 frames (the last few lag out)
    assert m and 15 <= int(m.group(1)) <= 21, run.stdout
    assert frame.status_code == 200 and other.status_code == 404
    t = float(frame.headers["x-frame-time-s"])
    assert CLIP_START <= t <= CLIP_START + 100 / 25
    img = cv2.imdecode(np.frombuffer(frame.content, np.uint8), cv2.IMREAD_GRAYSCALE)
    still = cv2.imread(str(site.sensor("cam1").image_path), cv2.IMREAD_GRAYSCALE)
    assert img.shape == still.shape == (720, 1280)
    assert np.abs(img.astype(float) - still).mean() < 6.0  # the clip is the still + noise
    boxes = json.loads(frame.headers["x-frame-boxes"])
    at_t = [list(b) for tt, b, _ in want if abs(tt - t) < 1e-6]
    assert boxes == at_t


def test_frames_that_cannot_be_posted_are_dropped_without_blocking():
    import socket

    notes: list[str] = []
    img = np.zeros((72, 128, 3), np.uint8)
    with socket.socket() as silent:  # accepts connections (backlog), never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        url = f"http://127.0.0.1:{silent.getsockname()[1]}"
        poster = FramePoster(url, "cam1", rate_hz=100, timeout_s=3, log=notes.append)
        # Every offer returns while the sender hangs on the silent server (else: timeout).
        assert all(poster.offer(k / 10, img, []) for k in range(30))
        assert poster.n_posted == 0
        poster.close(timeout_s=10)
    assert poster.n_posted == 0 and poster.n_failed >= 1
    assert poster.n_failed + poster.n_dropped == 30
    assert len(notes) == 1 and "frames not posted" in notes[0]


def test_rate_limit_is_in_video_time():
    poster = FramePoster("http://127.0.0.1:9", "cam1", rate_hz=4)
    img = np.zeros((8, 8), np.uint8)
    kept = [k for k in range(40) if poster.offer(100.0 + k / 25, img, [])]
    poster.close()
    assert kept == list(range(0, 40, 7))  # 0.28 s apart: the first frame 0.25 s on
