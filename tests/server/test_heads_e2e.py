"""A real uvicorn process with active heads: slew over HTTP, SIGKILL, restart, the slew is back."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import httpx2 as httpx
import pytest
from heads_helpers import active_site
from server_helpers import AUTH, TOKEN, start_server

pytestmark = pytest.mark.timeout(180)


def start(site, db):
    return start_server(site, db, "--heads", "sim")


def head_until(c, pred, timeout_s=30.0):
    deadline = time.monotonic() + timeout_s
    while True:
        body = c.get("/api/sensors/cam1/head").json()
        if pred(body) or time.monotonic() > deadline:
            return body
        time.sleep(0.1)


def test_slew_over_http_survives_sigkill(sample_site_dir, tmp_path):
    site = active_site(sample_site_dir, tmp_path / "site", {"cam1": {"active": True}})
    db = tmp_path / "console.sqlite3"
    proc, url = start(site, db)
    try:
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            r = c.put(
                "/api/sensors/cam1/slew", json={"pan_deg": 75.5, "tilt_deg": -12, "hfov_deg": 20}
            )
            assert r.status_code == 200, r.text
            body = head_until(
                c,
                lambda b: (
                    b["status"]
                    and not b["status"]["moving"]
                    and abs(b["status"]["pan_deg"] - 75.5) < 1e-6
                ),
            )
            st = body["status"]
            assert (st["pan_deg"], st["tilt_deg"], st["hfov_deg"]) == pytest.approx((75.5, -12, 20))
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    proc, url = start(site, db)
    try:
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            body = head_until(
                c, lambda b: b["status"] and abs(b["status"]["pan_deg"] - 75.5) < 1e-6
            )
            assert body["mode"] == "slew"
            assert body["target"] == {"pan_deg": 75.5, "tilt_deg": -12.0, "hfov_deg": 20.0}
            assert body["status"]["pan_deg"] == pytest.approx(75.5)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    assert (tmp_path / "console.sqlite3.heads.jsonl").is_file()


def test_a_bad_head_adapter_stops_serve_with_one_line(sample_site_dir, tmp_path):
    adapter = {
        "kind": "onvif",
        "url": "http://h/onvif",
        "profile": "p",
        "password_env": "UNSET_PW_7",
    }
    entry = {"active": True, "head_adapter": adapter}
    site = active_site(sample_site_dir, tmp_path / "site", {"cam3": entry})
    env = {k: v for k, v in os.environ.items() if k != "UNSET_PW_7"}
    proc = subprocess.run(
        [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(site),
         "--db", str(tmp_path / "c.sqlite3"), "--port", "0", "--no-warm-up"],
        capture_output=True, text=True, check=False, timeout=120,
        env={**env, "DEMTRACK_TOKEN": TOKEN},
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "cam3" in proc.stderr and "UNSET_PW_7 is not set" in proc.stderr
