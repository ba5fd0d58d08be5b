"""``POST /api/sensors/{id}/poses``: checks, durability, idempotency, export, current pose."""

from __future__ import annotations

import json

import numpy as np
import pytest
from server_helpers import AUTH, database_rows

from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.site.folder import load_site
from demtrack.server.footprints import footprint

T0 = 1_780_000_000.0  # 2026-05-28, a real UTC time


def poses(n: int, t0: float = T0, dt: float = 0.1, pan0: float = 10.0, **extra):
    return [
        {"t": round(t0 + k * dt, 6), "pan_deg": pan0 + k, "tilt_deg": -5.0, **extra}
        for k in range(n)
    ]


def post(c, sensor, records, key=None, headers=AUTH):
    body = {"poses": records} if key is None else {"poses": records, "batch_key": key}
    return c.post(
        f"/api/sensors/{sensor}/poses",
        headers={**headers, "Content-Type": "application/json"},
        content=json.dumps(body),  # json.dumps writes NaN, as a careless client would
    )


def test_ack_counts_each_reason_and_the_batch_is_durable(client, tmp_path, store_kw):
    good = poses(3)
    bad = [
        {"t": T0 + 1.0, "pan_deg": float("nan"), "tilt_deg": 0.0},  # not finite
        {"t": T0 + 1.1, "pan_deg": 1.0},  # no tilt
        {"t": T0 + 1.2, "pan_deg": 1.0, "tilt_deg": 95.0},  # beyond the zenith
        {"t": T0 + 1.3, "pan_deg": 1.0, "tilt_deg": 0.0, "hfov_deg": 30.0},  # zoom, none before
        {"t": T0 + 0.05, "pan_deg": 1.0, "tilt_deg": 0.0},  # older than the newest
        {"t": T0 + 0.2, "pan_deg": 1.0, "tilt_deg": 0.0},  # same time as the newest
        "not a record",
        {"time": "2026-05-28T20:26:41Z", "pan_deg": 3.0, "tilt_deg": 0.0},  # ISO, newer: kept
    ]
    r = post(client, "cam1", good + bad)
    assert r.status_code == 200, r.text
    ack = r.json()
    assert (ack["n_records"], ack["accepted"], ack["skipped"]) == (11, 4, 7)
    assert ack["counts"] == {
        "nan": 1,
        "malformed": 2,
        "out_of_range": 1,
        "mixed_fields": 1,
        "time_backwards": 1,
        "duplicate_time": 1,
    }
    assert sorted(i["index"] for i in ack["issues"]) == list(range(3, 10))
    assert all("\n" not in i["message"] for i in ack["issues"])
    # committed: another connection sees the rows as soon as the ack is back
    sql = "SELECT sensor, t_s, batch_id FROM poses ORDER BY t_s"
    rows = database_rows(tmp_path, store_kw, sql)
    assert [r[1] for r in rows] == [p["t"] for p in good] + [1_780_000_001.0]
    assert {r[0] for r in rows} == {"cam1"} and {r[2] for r in rows} == {ack["batch_id"]}


def test_order_is_kept_across_batches_and_per_sensor(client):
    assert post(client, "cam1", poses(5, t0=T0 + 10)).json()["accepted"] == 5
    ack = post(client, "cam1", poses(3, t0=T0)).json()
    assert ack["counts"] == {"time_backwards": 3} and ack["accepted"] == 0
    assert post(client, "cam2", poses(3, t0=T0)).json()["accepted"] == 3  # another sensor


def test_batch_key_makes_a_resend_harmless(client, tmp_path, store_kw):
    first = post(client, "cam1", poses(4), key="head1-0001").json()
    again = post(client, "cam1", poses(4), key="head1-0001").json()
    assert again["duplicate"] and not first["duplicate"]
    assert again["batch_id"] == first["batch_id"] and again["accepted"] == 4
    assert database_rows(tmp_path, store_kw, "SELECT COUNT(*) FROM poses") == [(4,)]


def test_unknown_sensor_auth_and_size_limits(client_factory):
    c = client_factory(max_batch=5)
    r = post(c, "nope", poses(2))
    assert r.status_code == 404 and "nope" in r.json()["detail"]
    assert post(c, "cam1", poses(2), headers={}).status_code == 401
    r = post(c, "cam1", poses(6))
    assert r.status_code == 413 and "limit is 5" in r.json()["detail"]


def test_export_round_trips_through_the_pose_file_reader(client, tmp_path):
    from demtrack.core.io import pose_io

    sent = poses(6, hfov_deg=40.0)
    post(client, "cam1", sent)
    got = client.get(
        "/api/sensors/cam1/poses", params={"t_from": T0 + 0.1, "t_to": T0 + 0.4}, headers=AUTH
    )
    assert got.status_code == 200
    body = got.json()
    assert body["sensor"] == "cam1"
    assert [p["t_s"] for p in body["poses"]] == [s["t"] for s in sent[1:5]]
    assert body["poses"][0]["time_utc"] == "2026-05-28T20:26:40.100Z"
    for fmt in ("csv", "jsonl"):
        r = client.get(f"/api/sensors/cam1/poses?format={fmt}", headers=AUTH)
        assert r.status_code == 200
        path = tmp_path / f"poses.{fmt}"
        path.write_text(r.text, encoding="utf-8")
        read, report = pose_io.read_poses(path)
        assert report.n_skipped == 0
        series = read["cam1"]
        assert np.array_equal(series.t_s, [s["t"] for s in sent])
        assert [p.pan_deg for p in series.samples()] == [s["pan_deg"] for s in sent]
        assert [p.hfov_deg for p in series.samples()] == [40.0] * 6
    assert client.get("/api/sensors/nope/poses", headers=AUTH).status_code == 404


def test_sensor_listing_shows_the_current_pose_and_its_footprint(client, sample_site_dir):
    before = client.get("/api/sensors/cam1", headers=AUTH).json()
    assert before["pose"] is None and before["telemetry"] is False
    post(client, "cam1", [{"t": T0, "pan_deg": before["pan_deg"] + 15.0, "tilt_deg": -8.0}])
    after = client.get("/api/sensors/cam1", headers=AUTH).json()
    assert after["telemetry"] is True and after["active"] is False
    assert after["pose"]["pan_deg"] == before["pan_deg"] + 15.0
    assert after["pan_deg"] == after["pose"]["pan_deg"] and after["tilt_deg"] == -8.0
    assert after["pose"]["time_utc"] == "2026-05-28T20:26:40.000Z"
    # the oracle: the footprint of the camera at that pose, computed here
    site = load_site(sample_site_dir)
    sensor = site.sensors["cam1"]
    cam = camera_at(sensor.head, PoseSample(T0, before["pan_deg"] + 15.0, -8.0))
    want = footprint(cam, site.dem.ray_caster(), site.frame)  # full detail
    got = np.array(after["footprint"]["enu"])
    assert after["footprint"]["n_rays"] == 32 and len(want["enu"]) == 2 * len(got)
    assert np.allclose(got, np.array(want["enu"])[::2], atol=0.005)  # 8 rays an edge, cm
    assert after["footprint"]["enu"] != before["footprint"]["enu"]


@pytest.mark.parametrize("n_bad", [0, 1])
def test_accept_takes_samples_from_a_head_adapter(client, n_bad):
    state = client.app.state.console
    samples = [PoseSample(T0 + k * 0.04, 5.0 + k, -3.0) for k in range(5)]
    if n_bad:
        samples.append(PoseSample(T0, 0.0, 0.0))  # older than what is there
    ack = state.poses.accept("cam2", samples, batch_key=f"sim-{n_bad}")
    assert ack["accepted"] == 5 and ack["skipped"] == n_bad and ack["sensor"] == "cam2"
    assert state.poses.current("cam2") == samples[4]
    assert [b["pan_deg"] for b in state.store.poses("cam2")] == [5.0, 6.0, 7.0, 8.0, 9.0]


def test_detection_records_carry_inline_poses_and_the_ack_counts_no_pose(client):
    from server_helpers import walk

    recs = [{**r, "pan_deg": 3.0 + k, "tilt_deg": -9.0} for k, r in enumerate(walk(n=3, t0=T0))]
    late = walk(n=1, t0=T0 + 5.0)  # 4.8 s after cam1's newest pose: none close enough
    r = client.post("/api/detections", headers=AUTH, json={"detections": recs + late})
    ack = r.json()
    assert r.status_code == 200 and ack["accepted"] == 4 and ack["poses"] == 3
    stored = client.get("/api/sensors/cam1/poses", headers=AUTH).json()["poses"]
    assert [(p["t_s"], p["pan_deg"]) for p in stored] == [
        (T0, 3.0),
        (T0 + 0.2, 4.0),
        (T0 + 0.4, 5.0),
    ]
    # the late detection falls behind the reorder horizon once cam2's newer one comes
    r = client.post(
        "/api/detections", headers=AUTH, json={"detections": walk(sensor="cam2", n=1, t0=T0 + 9)}
    )
    assert r.json()["no_pose"] == 0  # cam2's own detection had a pose (fixed camera)
    counts = client.get("/api/status", headers=AUTH).json()["counts"]
    assert counts["no_pose"] == 1 and counts["pose_waiting"] == 0
