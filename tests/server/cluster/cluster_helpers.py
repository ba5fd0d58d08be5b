"""Helpers of the cluster tests: real ``demtrack serve`` processes on one PostgreSQL database.

Imported by file name (tests are not a package). The servers are
``demtrack serve --database-url`` processes logging to files; batches are posted over HTTP and
the database is read directly to know when the tracker has caught up.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

import psycopg
from server_helpers import AUTH, TOKEN, scenario_records

__all__ = [
    "AUTH",
    "TOKEN",
    "get_json",
    "log_text",
    "post_batch",
    "scenario_batches",
    "serve_on",
    "stop",
    "stream_rows",
    "wait_tracked",
]

#: Scenarios posted: several targets (two cars passing, three people crossing).
SCENARIOS = ("passing-vehicles", "pedestrians")


def scenario_batches(site: Any, until_s: float, span_s: float = 0.5) -> list[list[dict]]:
    """The scenarios' detection records before ``until_s``, in time order, as batches of
    under ``span_s`` each (what a camera gateway would post)."""
    records = sorted(
        (r for name in SCENARIOS for r in scenario_records(site, name, until_s)),
        key=lambda r: (r["t"], r["sensor"]),
    )
    batches: list[list[dict]] = []
    for r in records:
        if not batches or r["t"] >= batches[-1][0]["t"] + span_s:
            batches.append([])
        batches[-1].append(r)
    return batches


def serve_on(site: Path, tmp: Path, name: str, database_url: str, ttl_s: float = 2.0):
    """``demtrack serve`` on ``database_url`` as a real process: ``(process, base URL)``.

    Its output goes to ``tmp/<name>.log`` (read it with :func:`log_text`).
    """
    tmp.mkdir(parents=True, exist_ok=True)
    log = tmp / f"{name}.log"
    env = {
        **os.environ,
        "DEMTRACK_TOKEN": TOKEN,
        "DEMTRACK_LEASE_TTL_S": str(ttl_s),
        "DEMTRACK_EVENTS": "false",
    }
    cmd = [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(site)]
    cmd += ["--db", str(tmp / f"{name}.sqlite3")]  # unused on PostgreSQL but the token's place
    cmd += ["--database-url", database_url, "--port", "0", "--no-warm-up", "--log-level", "info"]
    with log.open("w") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and proc.poll() is None:
        m = re.search(r"Uvicorn running on (http://[\d.]+:\d+)", log.read_text())
        if m:
            return proc, m.group(1)
        time.sleep(0.1)
    proc.kill()
    raise AssertionError(f"server {name} did not start:\n{log.read_text()[-3000:]}")


def log_text(tmp: Path, name: str) -> str:
    """What server ``name`` (started by :func:`serve_on` in ``tmp``) has logged."""
    return (tmp / f"{name}.log").read_text()


def stop(proc: Any) -> None:
    """Terminate a server process (if it still runs) and wait for it."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(30)
        except Exception:  # noqa: BLE001 - it would not stop: kill it
            proc.kill()
            proc.wait(30)


def post_batch(base: str, batch: list[dict]) -> dict:
    """POST one batch to ``base``'s ``/api/detections``; its acknowledgement."""
    req = urllib.request.Request(
        f"{base}/api/detections",
        data=json.dumps({"detections": batch}).encode(),
        headers={**AUTH, "Content-Type": "application/json"},
        method="POST",
    )
    with urllib.request.urlopen(req, timeout=60) as r:  # noqa: S310 - loopback
        assert r.status == 200
        return json.loads(r.read())


def get_json(base: str, path: str) -> Any:
    """GET ``path`` from ``base`` with the operator token; the decoded body."""
    req = urllib.request.Request(f"{base}{path}", headers=AUTH)
    with urllib.request.urlopen(req, timeout=60) as r:  # noqa: S310 - loopback
        return json.loads(r.read())


def wait_tracked(database_url: str, timeout_s: float = 300.0) -> int:
    """Wait until every stored detection has its fix (the tracker caught up); how many."""
    deadline = time.monotonic() + timeout_s
    with psycopg.connect(database_url, autocommit=True) as c:
        while True:
            n, pending = c.execute(
                "SELECT count(*), count(*) FILTER (WHERE f.detection_id IS NULL)"
                " FROM detections d LEFT JOIN fixes f ON f.detection_id = d.id"
            ).fetchone()
            if pending == 0:
                return int(n)
            assert time.monotonic() < deadline, f"{pending} of {n} detections never tracked"
            time.sleep(0.2)


def stream_rows(database_url: str) -> list[tuple[int, str]]:
    """The event log as stored: ``(seq, payload text)`` in order."""
    with psycopg.connect(database_url, autocommit=True) as c:
        return [
            (int(s), str(p)) for s, p in c.execute("SELECT seq, payload FROM events ORDER BY seq")
        ]
