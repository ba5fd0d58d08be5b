"""``demtrack watch --server`` against a real uvicorn that is SIGKILLed and restarted
mid-watch: every detection arrives once, the same ones a JSON Lines run writes."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx2 as httpx
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "core" / "video"))
from synth import Body, site_clip  # noqa: E402

from demtrack.core.site.folder import load_site  # noqa: E402

pytestmark = pytest.mark.timeout(600)
TOKEN = "watch-test-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(site: Path, db: Path, port: int) -> subprocess.Popen:
    env = {**os.environ, "DEMTRACK_TOKEN": TOKEN}
    cmd = [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(site), "--db", str(db)]
    proc = subprocess.Popen(
        [*cmd, "--port", str(port), "--no-warm-up", "--log-level", "info"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    deadline = time.monotonic() + 90
    assert proc.stdout is not None
    for line in proc.stdout:
        if re.search(r"Uvicorn running on http://[\d.]+:\d+", line):
            threading.Thread(target=proc.stdout.read, daemon=True).start()
            return proc
        if time.monotonic() > deadline:
            break
    proc.kill()
    raise AssertionError("server did not start")


def stored(url: str) -> list[dict]:
    with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
        return c.get("/api/detections", params={"limit": 10000}).json()


def test_watch_survives_a_server_restart_without_loss_or_duplicates(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    bodies = [
        Body("human", (300, 560), (1.4, 0.3), (0.55, 0.35, 1.75), frames=(4, 10**9)),
        Body("vehicle", (900, 500), (-6.0, 2.0), (1.8, 4.5, 1.5), grey=200, frames=(4, 10**9)),
    ]
    clip = site_clip(tmp_path / "cam1.mp4", site, "cam1", bodies, n_frames=150)
    watch = [sys.executable, "-m", "demtrack.cli", "watch", "--site", str(sample_site_dir)]
    watch += ["--sensor", "cam1", "--source", str(clip.path), "--batch-frames", "5", "--quiet"]

    # the reference: the same watch into a file
    ref = tmp_path / "ref.jsonl"
    subprocess.run([*watch, "-o", str(ref)], check=True, capture_output=True, timeout=300)
    want = sorted((r["t"], tuple(r["bbox"]), r["class"]) for r in map(json.loads, ref.open()))
    assert len(want) > 150

    port = free_port()
    url = f"http://127.0.0.1:{port}"
    db = tmp_path / "console.sqlite3"
    server = start_server(sample_site_dir, db, port)
    watcher = subprocess.Popen(
        [*watch, "--server", url, "--token", TOKEN],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while len(stored(url)) < 10:  # some batches are in
            assert time.monotonic() < deadline and watcher.poll() is None
            time.sleep(0.05)
        os.kill(server.pid, signal.SIGKILL)
        server.wait(10)
        time.sleep(2.0)  # the watcher keeps decoding and retrying meanwhile
        assert watcher.poll() is None, "the watcher should wait for the server"
        server = start_server(sample_site_dir, db, port)
        out, err = watcher.communicate(timeout=300)
        assert watcher.returncode == 0, err
        assert "unreachable" in err and "retrying" in err
        got = stored(url)
    finally:
        watcher.kill()
        server.kill()
        server.wait(10)
    assert len(got) == len(want)  # nothing lost, nothing twice
    assert sorted((d["t"], tuple(d["bbox"]), d["class"]) for d in got) == want
    assert f"{len(want)} detections to {url}" in out


def test_watch_posts_klv_poses_to_the_sensor(sample_site_dir, tmp_path):
    from synth import klv_clip
    from test_watch_command import sensor_datalinks

    site = load_site(sample_site_dir)
    path = klv_clip(tmp_path / "fmv.ts", sensor_datalinks(site))
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    server = start_server(sample_site_dir, tmp_path / "db.sqlite3", port)
    try:
        watch = [sys.executable, "-m", "demtrack.cli", "watch", "--site", str(sample_site_dir)]
        watch += ["--sensor", "cam1", "--source", str(path), "--start", "2026-11-18T09:46:40Z"]
        run = subprocess.run(
            [*watch, "--server", url, "--token", TOKEN, "--quiet"],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert run.returncode == 0, run.stderr
        assert "10 poses" in run.stdout
        # sent again: the same batch keys, nothing stored twice
        subprocess.run([*watch, "--server", url, "--token", TOKEN, "--quiet"], check=True,
                       capture_output=True, timeout=300)  # fmt: skip
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            poses = c.get("/api/sensors/cam1/poses", params={"format": "json"}).json()
    finally:
        server.kill()
        server.wait(10)
    rows = poses if isinstance(poses, list) else poses.get("poses", poses)
    assert len(rows) == 10
    assert sorted(r["pan_deg"] for r in rows) == pytest.approx([100.0 + k for k in range(10)])
