"""Helpers shared by the server tests (imported by file name: tests are not a package)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS
from demtrack.server.app import create_app
from demtrack.server.replay import scenario_stream as _scenario_stream

TOKEN = "test-operator-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def make_app(site: Path, tmp: Path, **overrides: Any):
    kw: dict[str, Any] = {
        "site": site,
        "db_path": tmp / "console.sqlite3",
        "token": TOKEN,
        "warm_up": False,
    }
    kw.update(overrides)
    return create_app(scenarios=SAMPLE_SCENARIOS, **kw)


def scenario_stream(site, names, t0_s: float, **kw: Any):
    """:func:`demtrack.server.replay.scenario_stream` of the sample site's scenarios."""
    return _scenario_stream(site, names, t0_s, source=SAMPLE_SCENARIOS, **kw)


def walk(
    sensor: str = "cam1",
    n: int = 30,
    t0: float = 0.0,
    dt: float = 0.2,
    u0: float = 520.0,
    du: float = 4.0,
    v: float = 520.0,
    cls: str = "vehicle",
) -> list[dict[str, Any]]:
    """Detection records of one object whose foot pixel walks across the image."""
    rng = np.random.default_rng(0)
    out = []
    for k in range(n):
        u = u0 + du * k + float(rng.normal(0, 0.3))
        out.append(
            {
                "t": round(t0 + dt * k, 6),
                "sensor": sensor,
                "bbox": [u - 20.0, v - 40.0, u + 20.0, v],
                "class": cls,
                "score": 0.9,
                "local_id": f"{sensor}-{k}",
            }
        )
    return out


def scenario_records(site, name: str, until_s: float, **extra: Any) -> list[dict[str, Any]]:
    """Detection records of the sample-site scenario ``name`` before ``until_s`` (scenario
    time), each with ``extra`` fields (e.g. ``score``)."""
    from demtrack.samplesite.scenarios import make_scenario

    return [
        {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, **extra}
        for d in make_scenario(site, name).detections
        if d.t_s < until_s
    ]


def vehicle_run_pipeline(site_dir: Path, tmp: Path, until_s: float):
    """A started kalman ``Pipeline`` on a fresh store, and the ``vehicle-run`` scenario's
    detection records before ``until_s`` (not yet ingested): ``(site, pipeline, records)``.
    """
    from demtrack.core.site.folder import load_site
    from demtrack.server.ingest.pipeline import Pipeline
    from demtrack.server.store.database import Store

    site = load_site(site_dir)
    records = scenario_records(site, "vehicle-run", until_s, score=0.5)
    p = Pipeline(site, Store(tmp / "f.sqlite3"), "kalman", lambda _m: None)
    p.start()
    return site, p, records


def time_batches(records: list[dict[str, Any]], span_s: float) -> list[list[dict[str, Any]]]:
    """Time-ordered detection ``records`` cut into batches each spanning under ``span_s``."""
    out: list[list[dict[str, Any]]] = []
    for r in records:
        if out and r["t"] < out[-1][0]["t"] + span_s:
            out[-1].append(r)
        else:
            out.append([r])
    return out


def post_in_time_batches(client, records: list[dict[str, Any]], span_s: float = 0.5) -> None:
    """POST time-ordered detection ``records`` as :func:`time_batches`; every batch must be
    accepted."""
    for batch in time_batches(records, span_s):
        r = client.post("/api/detections", headers=AUTH, json={"detections": batch})
        assert r.status_code == 200


def stored_messages(store) -> list[dict[str, Any]]:
    """Every message of ``store``'s event log, in sequence order."""
    out: list[dict[str, Any]] = []
    while rows := store.events_since(out[-1]["seq"] if out else 0, 5000):
        out += rows
    return out


def start_server(
    site: Path, db: Path, *args: str, timeout_s: float = 90.0, **extra_env: str
) -> tuple[Any, str]:
    """``demtrack serve`` on a free port as a real process; its URL once uvicorn runs.

    ``args`` are more ``serve`` options, ``extra_env`` more environment (the operator
    token is :data:`TOKEN`). The output pipe is drained in a thread so the server never
    blocks on it. Raises AssertionError (the process killed) when it does not start.
    """
    import os
    import re
    import subprocess
    import sys
    import threading
    import time

    env = {**os.environ, "DEMTRACK_TOKEN": TOKEN, **extra_env}
    cmd = [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(site), "--db", str(db)]
    cmd += ["--port", "0", "--no-warm-up", "--log-level", "info", *args]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
    )
    assert proc.stdout is not None
    deadline = time.monotonic() + timeout_s
    for line in proc.stdout:
        m = re.search(r"Uvicorn running on (http://[\d.]+:\d+)", line)
        if m:
            threading.Thread(target=proc.stdout.read, daemon=True).start()
            return proc, m.group(1)
        if time.monotonic() > deadline:
            break
    proc.kill()
    raise AssertionError("server did not start")


def database_rows(tmp: Path, store_kw: dict[str, Any], sql: str) -> list[tuple[Any, ...]]:
    """The rows of ``sql`` (no parameters) read on a connection of its own to the test's
    database: the PostgreSQL database ``store_kw`` names, else :func:`make_app`'s SQLite
    file under ``tmp``. What another process would see: only committed rows."""
    url = store_kw.get("database_url")
    if url:
        import psycopg

        with psycopg.connect(url) as conn:
            return [tuple(r) for r in conn.execute(sql.encode()).fetchall()]
    import sqlite3

    conn = sqlite3.connect(tmp / "console.sqlite3")
    try:
        return conn.execute(sql).fetchall()
    finally:
        conn.close()
