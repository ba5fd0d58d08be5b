"""``demtrack demo`` as a real process: URLs printed, a track moving, a clean Ctrl-C."""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time

import httpx2 as httpx
import pytest

from demtrack.cli import main

pytestmark = pytest.mark.timeout(420)


def read_lines(proc: subprocess.Popen, lines: queue.Queue) -> None:
    assert proc.stdout is not None
    for line in proc.stdout:  # drain all along so the server never blocks on the pipe
        lines.put(line)
    lines.put(None)


def wait_for(lines: queue.Queue, pattern: str, seen: list[str], timeout_s: float) -> re.Match:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=1.0)
        except queue.Empty:
            continue
        if line is None:
            break
        seen.append(line)
        m = re.search(pattern, line)
        if m:
            return m
    raise AssertionError(f"no line matching {pattern!r}; output:\n{''.join(seen)}")


def moving_track(tracks: list[dict]) -> dict | None:
    for t in tracks:
        pts = t["points"]
        if len(pts) >= 10:
            d = (
                (pts[-1]["e_m"] - pts[0]["e_m"]) ** 2 + (pts[-1]["n_m"] - pts[0]["n_m"]) ** 2
            ) ** 0.5
            if d > 3.0:
                return t
    return None


def test_demo_serves_the_console_with_a_moving_track(sample_site_dir, tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "demtrack.cli",
        "demo",
        "--site",
        str(sample_site_dir),
        "--db",
        str(tmp_path / "demo.sqlite3"),
        "--port",
        "0",
        "--viser-port",
        "0",
        "--speed",
        "2",
    ]
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEMTRACK_")}
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
    )
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=read_lines, args=(proc, lines), daemon=True).start()
    seen: list[str] = []
    try:
        console = wait_for(lines, r"console\s+(http://\S+)/\?token=(\S+)", seen, 300)
        view = wait_for(lines, r"3D view\s+(http://\S+)", seen, 30)
        base, token = console.group(1), console.group(2)
        auth = {"Authorization": f"Bearer {token}"}
        with httpx.Client(base_url=base, timeout=30) as c:
            health = c.get("/api/health").json()
            assert health["status"] == "ok" and health["viser_url"] == view.group(1)
            assert c.get("/").status_code == 200  # the console page
            assert c.get("/docs").status_code == 200
            assert c.get("/api/site").status_code == 401  # reads need the printed token
            assert c.get("/api/site", headers=auth).status_code == 200
            track = None
            deadline = time.monotonic() + 240
            while track is None and time.monotonic() < deadline:
                time.sleep(1.0)
                track = moving_track(c.get("/api/tracks", headers=auth).json()["tracks"])
            assert track is not None, "no moving track from the replay"
        assert httpx.get(view.group(1), timeout=30).status_code == 200  # viser's client
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            status = proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    assert status == 0, "".join(seen)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--speed", "0"], "--speed must be a positive number"),
        (["--viser-port", "70000"], "--viser-port must be within 0..65535"),
    ],
)
def test_demo_bad_options_are_one_line(capsys, sample_site_dir, tmp_path, argv, message):
    status = main(
        ["demo", "--site", str(sample_site_dir), "--db", str(tmp_path / "d.sqlite3"), *argv]
    )
    err = capsys.readouterr().err
    assert status == 2 and message in err and err.count("\n") == 1
