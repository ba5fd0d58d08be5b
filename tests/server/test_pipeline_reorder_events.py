"""The pipeline's reorder buffer and live events, on the sample site with real SQLite files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from server_helpers import walk

from demtrack.core.activity.loitering import LoiterParams
from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.live_events import LiveEventParams
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


@pytest.fixture(scope="module")
def scenario_records(site):
    """The first 18 s of the vehicle-run scenario (three cameras), as ingest records."""
    sc = make_scenario(site, "vehicle-run")
    return [
        {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": d.score}
        for d in sc.detections
        if d.t_s < 18.0
    ]


def _pipeline(site, path: Path, **kw) -> tuple[Pipeline, list[dict]]:
    msgs: list[dict] = []
    p = Pipeline(site, Store(path), "kalman", msgs.extend, **kw)
    p.start()
    return p, msgs


def _slices(records, span_s=0.4):
    out: dict[int, list[dict]] = {}
    for r in records:
        out.setdefault(int(r["t"] // span_s), []).append(r)
    return [out[k] for k in sorted(out)]


def _geometry(p: Pipeline) -> list:
    """Tracks as (id, cls, [(t, e, n, u, sensors, detections)]) with detections by content."""
    dets = {i: (d.t_s, d.sensor, d.bbox) for i, d in p.store.detections(0, 100_000)}
    return [
        (
            b["id"],
            b["cls"],
            [
                (q["t_s"], q["e_m"], q["n_m"], q["u_m"], q["sensors"])
                + tuple(dets[i] for i in q["detection_ids"])
                for q in b["points"]
            ],
        )
        for b in p.store.tracks()
    ]


def test_shuffled_batches_within_the_lag_track_like_ordered_ones(site, scenario_records, tmp_path):
    slices = _slices(scenario_records)
    ordered, _ = _pipeline(site, tmp_path / "a.sqlite3", reorder_lag_s=0.5)
    for batch in slices:
        ordered.ingest(batch)
    # Each camera sends its own batch per 0.4 s slice, in a random order within the slice:
    # a batch may be up to 0.4 s older than one already received.
    rng = np.random.default_rng(0)
    shuffled, _ = _pipeline(site, tmp_path / "b.sqlite3", reorder_lag_s=0.5)
    n_out_of_order = 0
    for batch in slices:
        per_sensor: dict[str, list[dict]] = {}
        for r in batch:
            per_sensor.setdefault(r["sensor"], []).append(r)
        parts = [per_sensor[s] for s in rng.permutation(sorted(per_sensor))]
        n_out_of_order += any(a[0]["t"] > b[0]["t"] for a, b in zip(parts, parts[1:], strict=False))
        for part in parts:
            shuffled.ingest(part)
    assert n_out_of_order >= 3  # the shuffle really reorders
    assert ordered.n_late == shuffled.n_late == 0
    assert shuffled.n_buffered == ordered.n_buffered > 0
    a, b = _geometry(ordered), _geometry(shuffled)
    assert len(a) >= 1 and sum(len(t[2]) for t in a) > 50
    assert a == b
    # Without the buffer the same arrival order loses fixes to lateness.
    late, _ = _pipeline(site, tmp_path / "c.sqlite3", reorder_lag_s=0.0)
    rng = np.random.default_rng(0)
    for batch in slices:
        per_sensor = {}
        for r in batch:
            per_sensor.setdefault(r["sensor"], []).append(r)
        for s in rng.permutation(sorted(per_sensor)):
            late.ingest(per_sensor[s])
    assert late.n_late > 0
    stored = late.store.fixes(0, 100_000)
    assert sum(1 for f in stored if f["hits"] is not None and not f["tracked"]) == late.n_late


def test_restart_rebuilds_tracker_and_reorder_buffer(site, scenario_records, tmp_path):
    slices = _slices(scenario_records)
    half = len(slices) // 2
    whole, _ = _pipeline(site, tmp_path / "whole.sqlite3", reorder_lag_s=0.8)
    for batch in slices:
        whole.ingest(batch)
    path = tmp_path / "cut.sqlite3"
    first, _ = _pipeline(site, path, reorder_lag_s=0.8)
    for batch in slices[:half]:
        first.ingest(batch)
    buffered = first.n_buffered
    first.store.close()
    again, _ = _pipeline(site, path, reorder_lag_s=0.8)
    assert again.n_buffered == buffered > 0
    for batch in slices[half:]:
        again.ingest(batch)
    assert _geometry(again) == _geometry(whole)


def test_a_person_standing_still_loiters_once(site, tmp_path):
    # 24 s standing still (u does not move), then walking away fast.
    still = walk(sensor="cam1", n=120, dt=0.2, du=0.0, cls="human", u0=500.0, v=560.0)
    away = walk(sensor="cam1", n=40, t0=24.0, dt=0.2, du=12.0, cls="human", u0=500.0, v=560.0)
    params = LiveEventParams(
        every_s=1.0, window_s=60.0, loiter=LoiterParams(radius_m=3.0, min_duration_s=8.0)
    )
    p, msgs = _pipeline(site, tmp_path / "e.sqlite3", events=params)
    for k in range(0, len(still + away), 5):
        p.ingest((still + away)[k : k + 5])
    loiter = p.store.activity(kinds=["loitering"])
    assert len(loiter) == 1, loiter  # evaluated every second, stored once
    ev = loiter[0]
    assert ev["t_start_s"] <= 2.0 and 18.0 <= ev["t_end_s"] <= 28.0
    assert ev["sensors"] == ["cam1"] and ev["details"]["extent_radius_m"] <= 3.0
    streamed = [m for m in msgs if m["type"] == "event" and m["kind"] == "loitering"]
    states = [m["event"]["state"] for m in streamed]
    assert states == ["start", "end"] and not ev["open"]
    assert all(m["event"]["key"] == ev["key"] for m in streamed)
    # stream order: sequence numbers increase and the event log holds the same messages
    seqs = [m["seq"] for m in msgs]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    stored = p.store.events_since(0, 100_000)
    assert [m for m in stored if m["type"] == "event" and m["kind"] == "loitering"] == streamed


def test_zone_entry_is_reported_once(site, tmp_path):
    rec = walk(sensor="cam1", n=60, dt=0.2, du=6.0, cls="human", u0=300.0, v=560.0)
    geo = site.geolocator()
    cam = site.sensors["cam1"].camera
    u = np.array([0.5 * (r["bbox"][0] + r["bbox"][2]) for r in rec])
    v = np.array([r["bbox"][3] for r in rec])
    first = [g.hits[0].p_enu for g in geo.geolocate(cam, u, v, rule="all") if g.hits]
    path = np.array(first)
    # A square around the second half of the walk.
    e0, n0 = path[len(path) // 2 :, :2].min(axis=0) - 3.0
    e1, n1 = path[len(path) // 2 :, :2].max(axis=0) + 3.0
    corners = [(e0, n0), (e1, n0), (e1, n1), (e0, n1), (e0, n0)]
    ring = []
    for e, n in corners:
        lat, lon, _ = site.frame.to_geodetic(e, n, 0.0)
        ring.append([float(lon), float(lat)])
    zones = tmp_path / "zones.geojson"
    feature = {"type": "Feature", "properties": {"name": "yard"}}
    feature["geometry"] = {"type": "Polygon", "coordinates": [ring]}
    zones.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    p, msgs = _pipeline(
        site, tmp_path / "z.sqlite3", events=LiveEventParams(every_s=0.5), zones_path=zones
    )
    for k in range(0, len(rec), 3):
        p.ingest(rec[k : k + 3])
    enter = p.store.activity(kinds=["zone-enter"])
    assert len(enter) == 1 and enter[0]["details"]["zone"] == "yard"
    t_mid = rec[len(rec) // 2]["t"]
    assert abs(enter[0]["t_start_s"] - t_mid) < 2.0
    assert p.store.activity(kinds=["zone-leave"]) == []
    assert sum(1 for m in msgs if m["type"] == "event" and m["kind"] == "zone-enter") == 1


def test_handoff_predictions_name_real_sensors(site, scenario_records, tmp_path):
    p, msgs = _pipeline(site, tmp_path / "h.sqlite3", events=LiveEventParams())
    for batch in _slices(scenario_records, 0.5):
        p.ingest(batch)
    handoffs = p.store.activity(kinds=["handoff"])
    assert handoffs, "the vehicle run crosses camera boundaries"
    for h in handoffs:
        d = h["details"]
        assert d["current"] in site.sensors and d["next_sensor"] in site.sensors
        assert d["current"] != d["next_sensor"]
        assert h["t_end_s"] == d["exit_t_s"] >= h["t_start_s"]
    confirmed = p.store.activity(kinds=["track_confirmed"])
    assert {e["track_ids"][0] for e in confirmed} == {b["id"] for b in p.store.tracks()}
