"""Benchmark: pose telemetry through the server, against detections in the same run.

On the sample site, in-process (FastAPI ``TestClient``, a fresh database, WAL with
``synchronous=FULL``: each batch is durable before its acknowledgement):

1. **Ingest**: ``--batches`` POSTs of ``--batch`` pose samples to
   ``/api/sensors/cam1/poses``, then as many POSTs of ``--batch`` detections of a fixed
   camera to ``/api/detections``; poses/s and detections/s and their ratio.
2. **Posed geolocation**: the same detections processed by the pipeline once with
   ``cam1`` fixed and once with ``cam1`` telemetry-driven (a pose series every 0.05 s,
   loaded before): wall time per detection of each and the ratio posed / fixed.

Only ratios from one run are meant to be compared (the machine is shared). Usage:
``uv run python -m demtrack.bench.pose_ingest [--site DIR] [--batches 20] [--batch 200]``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["main"]

T0 = 1_780_000_000.0


def _walk(n: int, t0: float, sensor: str = "cam1") -> list[dict[str, Any]]:
    rng = np.random.default_rng(0)
    out = []
    for k in range(n):
        u = 500.0 + (k % 200) * 2.0 + float(rng.normal(0, 0.3))
        t = round(t0 + 0.01 * k, 6)
        out.append(
            {"t": t, "sensor": sensor, "bbox": [u - 20, 480.0, u + 20, 520.0], "class": "vehicle"}
        )
    return out


def _ingest_rates(site: Path, tmp: Path, n_batches: int, batch: int) -> tuple[float, float]:
    from fastapi.testclient import TestClient

    from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS
    from demtrack.server.app import create_app

    token = "bench-token"
    auth = {"Authorization": f"Bearer {token}"}
    app = create_app(
        scenarios=SAMPLE_SCENARIOS, site=site, db_path=tmp / "b.sqlite3", token=token,
        warm_up=False, events=False, max_batch=max(batch, 1000),
    )  # fmt: skip
    with TestClient(app) as c:
        c.post("/api/detections", headers=auth, json={"detections": _walk(5, T0 - 100, "cam2")})
        t = time.perf_counter()
        for k in range(n_batches):
            poses = [
                {"t": T0 + (k * batch + i) * 0.01, "pan_deg": 10.0 + 0.001 * i, "tilt_deg": -5.0}
                for i in range(batch)
            ]
            r = c.post("/api/sensors/cam1/poses", headers=auth, json={"poses": poses})
            assert r.json()["accepted"] == batch
        pose_rate = n_batches * batch / (time.perf_counter() - t)
        t = time.perf_counter()
        for k in range(n_batches):
            recs = _walk(batch, T0 + k * batch * 0.01, "cam2")
            r = c.post("/api/detections", headers=auth, json={"detections": recs})
            assert r.json()["accepted"] == batch
        det_rate = n_batches * batch / (time.perf_counter() - t)
    return pose_rate, det_rate


def _geolocation_cost(site_dir: Path, tmp: Path, n: int) -> tuple[float, float, int]:
    from demtrack.core.camera.pose_series import PoseSample
    from demtrack.core.site.folder import load_site
    from demtrack.server.ingest.pipeline import Pipeline
    from demtrack.server.store.database import Store

    site = load_site(site_dir)
    cam = site.sensors["cam1"]
    recs = _walk(n, T0)
    out = []
    for name, posed in (("fixed", False), ("posed", True)):
        p = Pipeline(site, Store(tmp / f"{name}.sqlite3"), "kalman", lambda _m: None)
        p.start()
        if posed:
            samples = [
                PoseSample(T0 + 0.05 * k, cam.pan_deg + 0.002 * k, cam.tilt_deg)
                for k in range(int(n * 0.01 / 0.05) + 20)
            ]
            p.ingest_poses("cam1", samples)
        p.ingest(recs[:50])  # warm
        t = time.perf_counter()
        for k in range(50, n, 200):
            p.ingest(recs[k : k + 200])
        out.append((time.perf_counter() - t) / (n - 50))
        p.store.close()
    return out[0], out[1], p.pose_book.n_no_pose


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; print the rates and ratios."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--site", type=Path, default=None)
    ap.add_argument("--batches", type=int, default=20)
    ap.add_argument("--batch", type=int, default=200)
    ap.add_argument("--detections", type=int, default=2050)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        site = args.site
        if site is None:
            from demtrack.samplesite.build import build_sample_site

            site = build_sample_site(tmp / "site")
        poses_s, dets_s = _ingest_rates(site, tmp, args.batches, args.batch)
        fixed, posed, n_no_pose = _geolocation_cost(site, tmp, args.detections)
    sys.stdout.write(
        f"ingest: {poses_s:,.0f} poses/s, {dets_s:,.0f} detections/s"
        f" (poses / detections {poses_s / dets_s:.2f}x; batches of {args.batch})\n"
        f"pipeline per detection: fixed {fixed * 1e6:.0f} us, posed {posed * 1e6:.0f} us"
        f" (posed / fixed {posed / fixed:.2f}x; {n_no_pose} no_pose)\n"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
