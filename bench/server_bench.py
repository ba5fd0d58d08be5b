"""Benchmark: the console server's ingest rate and WebSocket fan-out latency, on loopback.

A real ``demtrack serve`` process (uvicorn) on the sample site, a fresh database:

1. **Ingest**: the sample scenarios' detections (the three played at once, repeated,
   shifted in time, to the requested count) are posted twice over, as a camera gateway
   would (``--batch`` detections per POST, one client, each batch after the previous
   one's acknowledgement) and as the camera processes do (one batch per camera per
   10 Hz frame, every camera of a frame posting at once on its own connection, the next
   frame once they are acknowledged: what ``server/replay.py`` hands the pipeline). A
   batch is acknowledged once it is durable (committed, WAL, ``synchronous=FULL``) *and*
   geolocated, tracked, its events detected and its messages stored and published, so
   detections / wall time is the sustained rate through the whole path - ingested and
   tracked, not queued: only the newest ``DEMTRACK_REORDER_LAG_S`` (0.5 s of scenario
   time) waits in the reorder buffer at the end, and the server's count of late
   (untracked) fixes is printed. The durable-storage rate alone (validation and the
   committed insert, no HTTP) is measured in-process on the gateway batches for
   comparison.
2. **Fan-out**: ``--clients`` WebSocket clients connect; single-detection batches are
   posted ``--rate`` times a second; for every batch each client notes when its
   ``ingest`` event message arrives. Latency = arrival - the moment the POST was sent
   (so it includes processing the one detection: an upper bound of the pure fan-out);
   the acknowledgement latency is printed beside it.

Targets (issue 3, 2 cores): 5,000 detections/s ingested and tracked; p95 fan-out latency
under 50 ms. Usage: ``demtrack bench server [--site DIR] [--detections 20000]
[--batch 500] [--clients 50] [--messages 200]``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from .sample_site import site_or_sample

__all__ = ["frame_batches", "main", "scenario_records"]

_TOKEN = "bench-operator-token"
_TARGET_RATE = 5000.0
_TARGET_P95_MS = 50.0


def scenario_records(site_dir: Path, n: int) -> list[dict[str, Any]]:
    """``n`` detection records from the sample scenarios, repeated later in time as needed."""
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.scenarios import make_scenario

    site = load_site(site_dir)
    base: list[dict[str, Any]] = []
    for name in ("vehicle-run", "pedestrians", "passing-vehicles"):
        for d in make_scenario(site, name).detections:
            base.append({"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls})
    # The scenarios overlap in time: merge them into one time-ordered stream.
    base.sort(key=lambda r: (r["t"], r["sensor"]))
    span = base[-1]["t"] + 10.0
    out: list[dict[str, Any]] = []
    k = 0
    while len(out) < n:
        out += [dict(r, t=round(r["t"] + k * span, 6)) for r in base[: n - len(out)]]
        k += 1
    return out


def _start_server(
    site: Path, db: Path, database_url: str | None = None
) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, "DEMTRACK_TOKEN": _TOKEN}
    env.pop("DEMTRACK_DATABASE_URL", None)  # the store is the one this run names
    more = [] if database_url is None else ["--database-url", database_url]
    proc = subprocess.Popen(
        [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(site), "--db", str(db)]
        + ["--port", "0", "--log-level", "info", *more],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    assert proc.stdout is not None
    for line in proc.stdout:
        m = re.search(r"Uvicorn running on (http://[\d.]+:\d+)", line)
        if m:
            threading.Thread(target=proc.stdout.read, daemon=True).start()
            return proc, m.group(1)
    proc.kill()
    raise RuntimeError("the server did not start (see demtrack serve's output)")


def frame_batches(records: list[dict[str, Any]]) -> list[list[list[dict[str, Any]]]]:
    """``records`` as frames (by time): each a list of per-camera batches, sensor order."""
    frames: dict[float, dict[str, list[dict[str, Any]]]] = {}
    for r in records:
        frames.setdefault(r["t"], {}).setdefault(r["sensor"], []).append(r)
    return [[frames[t][s] for s in sorted(frames[t])] for t in sorted(frames)]


def _ingest_frames(url: str, frames: list[list[list[dict[str, Any]]]]) -> tuple[float, int, int]:
    """Post each frame's per-camera batches at once (one connection per camera slot).

    Returns wall time (s), detections accepted and POSTs made.
    """
    from concurrent.futures import ThreadPoolExecutor

    import httpx2 as httpx

    headers = {"Authorization": f"Bearer {_TOKEN}"}
    width = max(len(f) for f in frames)
    clients = [httpx.Client(base_url=url, headers=headers, timeout=600) for _ in range(width)]

    def post(k: int, batch: list[dict[str, Any]]) -> int:
        r = clients[k].post("/api/detections", json={"detections": batch})
        r.raise_for_status()
        return int(r.json()["accepted"])

    accepted = posts = 0
    try:
        with ThreadPoolExecutor(width) as pool:
            t0 = time.perf_counter()
            for frame in frames:
                accepted += sum(pool.map(post, range(len(frame)), frame))
                posts += len(frame)
            wall = time.perf_counter() - t0
    finally:
        for c in clients:
            c.close()
    return wall, accepted, posts


def _status_counts(url: str) -> dict[str, int]:
    import httpx2 as httpx

    headers = {"Authorization": f"Bearer {_TOKEN}"}
    r = httpx.get(url + "/api/status", headers=headers, timeout=60)
    r.raise_for_status()
    return {k: int(v) for k, v in r.json()["counts"].items()}


def _ingest(url: str, batches: list[list[dict[str, Any]]]) -> tuple[float, int]:
    import httpx2 as httpx

    headers = {"Authorization": f"Bearer {_TOKEN}"}
    accepted = 0
    with httpx.Client(base_url=url, headers=headers, timeout=600) as c:
        t0 = time.perf_counter()
        for b in batches:
            r = c.post("/api/detections", json={"detections": b})
            r.raise_for_status()
            accepted += r.json()["accepted"]
        return time.perf_counter() - t0, accepted


def _durable_only(
    site_dir: Path, batches: list[list[dict[str, Any]]], database_url: str | None = None
) -> float:
    """Validation and committed inserts alone, in-process (detections/s)."""
    from demtrack.core.site.folder import load_site
    from demtrack.server.ingest.pipeline import Pipeline
    from demtrack.server.store.opening import open_store

    site = load_site(site_dir)
    with tempfile.TemporaryDirectory() as tmp:
        store = open_store(database_url or Path(tmp) / "d.sqlite3")
        p = Pipeline(site, store, "kalman", lambda _m: None)
        n, t0 = 0, time.perf_counter()
        for b in batches:
            dets, ack = p._validate(b)
            store.insert_batch(dets, ack, None)
            for d in dets:
                p._last_t[d.sensor] = max(d.t_s, p._last_t.get(d.sensor, d.t_s))
            n += len(dets)
        dt = time.perf_counter() - t0
        store.close()
    return n / dt


async def _fan_out(
    url: str, n_clients: int, n_messages: int, rate_hz: float, t_start: float, record: dict
) -> tuple[np.ndarray, np.ndarray]:
    import httpx2 as httpx
    import websockets

    ws_url = url.replace("http://", "ws://") + f"/ws?token={_TOKEN}"
    sent: dict[int, float] = {}
    arrivals: list[tuple[int, float]] = []
    ready = asyncio.Event()
    connected = 0

    async def client() -> None:
        nonlocal connected
        async with websockets.connect(ws_url, max_size=None) as ws:
            await ws.recv()  # hello
            connected += 1
            if connected == n_clients:
                ready.set()
            while True:
                raw = await ws.recv()
                now = time.perf_counter()
                text = raw.decode() if isinstance(raw, bytes) else raw
                if '"kind":"ingest"' not in text.replace(" ", ""):
                    continue
                m = re.search(r"batch (\d+):", json.loads(text)["text"])
                if m:
                    arrivals.append((int(m.group(1)), now))

    tasks = [asyncio.create_task(client()) for _ in range(n_clients)]
    await asyncio.wait_for(ready.wait(), 120)
    acks = []
    headers = {"Authorization": f"Bearer {_TOKEN}"}
    async with httpx.AsyncClient(base_url=url, headers=headers, timeout=60) as c:
        for k in range(n_messages):
            rec = dict(record, t=t_start + k / rate_hz)
            t0 = time.perf_counter()
            r = await c.post("/api/detections", json={"detections": [rec]})
            acks.append(time.perf_counter() - t0)
            sent[r.json()["batch_id"]] = t0
            await asyncio.sleep(max(0.0, 1.0 / rate_hz - (time.perf_counter() - t0)))
    deadline = time.perf_counter() + 10
    while time.perf_counter() < deadline:
        if sum(1 for b, _ in arrivals if b in sent) >= n_clients * n_messages:
            break
        await asyncio.sleep(0.05)
    for t in tasks:
        t.cancel()
    for t in tasks:
        with contextlib.suppress(BaseException):
            await t
    lat = np.array([t - sent[b] for b, t in arrivals if b in sent])
    return lat, np.array(acks)


def _measure(
    site: Path,
    tmp: Path,
    batches: list[list[dict[str, Any]]],
    frames: list[list[list[dict[str, Any]]]],
    pg: Any = None,
    fan_out: Any = None,
) -> dict[str, Any]:
    """The ingest figures on one store: SQLite, or fresh PostgreSQL databases.

    ``pg``: None for SQLite, else a factory of context managers each giving a new
    database URL; ``fan_out(url)``, when given, measures the fan-out on the same server.
    """
    with contextlib.ExitStack() as stack:
        durable_url = None if pg is None else stack.enter_context(pg())
        server_url = None if pg is None else stack.enter_context(pg())
        out: dict[str, Any] = {"durable": _durable_only(site, batches, durable_url)}
        name = "sqlite" if pg is None else "postgres"
        db = Path(tempfile.mkdtemp(dir=tmp)) / f"bench-{name}.sqlite3"  # fresh every round
        proc, url = _start_server(site, db, server_url)
        try:
            out["wall"], out["accepted"] = _ingest(url, batches)
            before = _status_counts(url)
            out["f_wall"], out["f_accepted"], out["f_posts"] = _ingest_frames(url, frames)
            after = _status_counts(url)
            out["late"] = after["late_fixes"]
            out["f_commits"] = after["ingest_commits"] - before["ingest_commits"]
            out["fan_out"] = None if fan_out is None else fan_out(url)
        finally:
            proc.kill()
            proc.wait(10)
    out["rate"] = out["accepted"] / out["wall"]
    out["f_rate"] = out["f_accepted"] / out["f_wall"]
    return out


def _print_ingest(m: dict[str, Any], label: str) -> None:
    print(
        f"  [{label}] ingest, durable + geolocated + tracked + events (HTTP): {m['rate']:8.0f}"
        f" det/s ({m['accepted']} in {m['wall']:.1f} s; target {_TARGET_RATE:.0f}:"
        f" {m['rate'] / _TARGET_RATE:.2f} x)"
    )
    print(
        f"  [{label}] the same, per-camera 10 Hz frame batches (cameras at once):"
        f" {m['f_rate']:8.0f} det/s ({m['f_accepted']} in {m['f_wall']:.1f} s, {m['f_posts']}"
        f" POSTs of {m['f_accepted'] / m['f_posts']:.1f} detections in {m['f_commits']} group"
        f" commits; target: {m['f_rate'] / _TARGET_RATE:.2f} x)"
    )
    print(f"  [{label}] late fixes (stored, not tracked): {m['late']}")
    print(
        f"  [{label}] durable storage only (validate + committed insert): {m['durable']:8.0f} det/s"
    )


def _ratios(pg: dict[str, Any], lite: dict[str, Any]) -> tuple[float, float, float]:
    """PostgreSQL's rates over SQLite's: gateway batches, frame batches, durable only."""
    return (
        pg["rate"] / lite["rate"],
        pg["f_rate"] / lite["f_rate"],
        pg["durable"] / lite["durable"],
    )


def _postgres(args: argparse.Namespace, stack: contextlib.ExitStack, tmp: Path) -> Any:
    """A factory of fresh database URLs on ``--database-url``'s server or a temporary one."""
    from .pg_temp import fresh_database, temp_server

    server = args.database_url or stack.enter_context(temp_server(tmp / "pg"))
    return lambda: fresh_database(server)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures; returns the exit status."""
    p = argparse.ArgumentParser(prog="demtrack bench server", description=__doc__.split("\n")[0])
    p.add_argument("--site", type=Path, help="sample site folder (default: build one, ~40 s)")
    p.add_argument("--detections", type=int, default=20_000, help="detections to ingest")
    p.add_argument("--batch", type=int, default=500, help="detections per POST")
    p.add_argument("--clients", type=int, default=50, help="WebSocket clients")
    p.add_argument("--messages", type=int, default=200, help="batches timed for fan-out")
    p.add_argument("--rate", type=float, default=20.0, help="fan-out batches per second")
    p.add_argument(
        "--database-url",
        metavar="URL",
        help="also run the ingest on PostgreSQL, in fresh databases made on this server (its"
        " role needs CREATEDB), and print the PostgreSQL/SQLite ratios",
    )
    p.add_argument(
        "--postgres",
        action="store_true",
        help="as --database-url, on a throw-away PostgreSQL server of its own",
    )
    p.add_argument(
        "--rounds",
        type=int,
        default=1,
        help="with PostgreSQL: measure both this many times, alternating which goes first,"
        " and print each round's ratios and their median (a loaded machine drifts)",
    )
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp_name, contextlib.ExitStack() as stack:
        tmp = Path(tmp_name)
        site = site_or_sample(args.site, tmp, announce=True)
        both = scenario_records(site, 2 * args.detections)
        recs, later = both[: args.detections], both[args.detections :]
        batches = [recs[i : i + args.batch] for i in range(0, len(recs), args.batch)]
        frames = frame_batches(later)
        last = later[-1]
        record = {k: last[k] for k in ("sensor", "bbox", "class")}

        def fan_out(url: str) -> tuple[np.ndarray, np.ndarray]:
            return asyncio.run(
                _fan_out(url, args.clients, args.messages, args.rate, last["t"] + 60.0, record)
            )

        lite = _measure(site, tmp, batches, frames, fan_out=fan_out)
        pg = None
        ratios: list[tuple[float, float, float]] = []
        if args.database_url or args.postgres:
            fresh = _postgres(args, stack, tmp)
            pg = _measure(site, tmp, batches, frames, fresh)
            ratios.append(_ratios(pg, lite))
            for k in range(1, args.rounds):  # alternate which goes first: load drifts
                first, second = (fresh, None) if k % 2 else (None, fresh)
                a = _measure(site, tmp, batches, frames, first)
                b = _measure(site, tmp, batches, frames, second)
                ratios.append(_ratios(a, b) if k % 2 else _ratios(b, a))
    lat, acks = lite["fan_out"]
    cpus = os.cpu_count()
    print(f"demtrack bench server: {len(recs)} detections in batches of {args.batch}, {cpus} CPUs")
    _print_ingest(lite, "sqlite")
    if pg is not None:
        _print_ingest(pg, "postgres")
        for k, (g, f, d) in enumerate(ratios):
            print(
                f"  PostgreSQL / SQLite, round {k + 1} (same input): gateway batches {g:.2f},"
                f" frame batches {f:.2f}, durable storage only {d:.2f}"
            )
        med = np.median(np.array(ratios), axis=0)
        print(
            f"  PostgreSQL / SQLite, median of {len(ratios)} round(s): gateway batches"
            f" {med[0]:.2f}, frame batches {med[1]:.2f}, durable storage only {med[2]:.2f}"
            " (bar: at least 0.5)"
        )
    if len(lat):
        med, p95 = (1000 * float(np.percentile(lat, q)) for q in (50, 95))
        amed, ap95 = (1000 * float(np.percentile(acks, q)) for q in (50, 95))
        got = len(lat) / max(args.clients * args.messages, 1)
        print(
            f"  fan-out to {args.clients} WebSocket clients, POST -> message: median"
            f" {med:.1f} ms, p95 {p95:.1f} ms (target p95 < {_TARGET_P95_MS:.0f} ms;"
            f" {100 * got:.1f} % of messages seen)"
        )
        print(f"  POST -> acknowledgement (1 detection): median {amed:.1f} ms, p95 {ap95:.1f} ms")
    else:
        print("  fan-out: no message arrived")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
