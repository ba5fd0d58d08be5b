"""``/api/sensors/{id}/slew|follow|head`` over TestClient, a restart, and one real-uvicorn run."""

from __future__ import annotations

import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from heads_helpers import active_site
from server_helpers import AUTH, make_app, post_in_time_batches, scenario_records

from demtrack.core.site.folder import load_site
from demtrack.core.visibility.viewshed import target_visible_fraction

pytestmark = pytest.mark.timeout(180)

ACTIVE = {
    "cam1": {"active": True, "slew_limits": {"pan_rate_deg_s": 90.0, "accel_deg_s2": 180.0}},
    "cam3": {"active": True},
}


@pytest.fixture(scope="module")
def site_dir(sample_site_dir, tmp_path_factory):
    return active_site(sample_site_dir, tmp_path_factory.mktemp("active") / "site", ACTIVE)


def wait_for(client, sensor, pred, timeout_s=20.0):
    """GET the head until ``pred(body)`` holds (the controller ticks in its own thread)."""
    deadline = time.monotonic() + timeout_s
    while True:
        body = client.get(f"/api/sensors/{sensor}/head", headers=AUTH).json()
        if pred(body) or time.monotonic() > deadline:
            return body
        time.sleep(0.05)


def ground_points(site_dir):
    """One ground point cam1 sees and one it cannot (terrain between), site frame (m)."""
    site = load_site(site_dir)
    cam = site.sensor("cam1").camera
    xy = np.stack(np.meshgrid(np.arange(-150, 150, 10.0), np.arange(-150, 150, 10.0)), -1)
    xy = xy.reshape(-1, 2)
    z = site.dem.sample(xy[:, 0], xy[:, 1])
    pts = np.column_stack([xy, z])[np.isfinite(z)]
    seen = target_visible_fraction(site.dem, cam, pts, 1.5, in_view=False, max_range_m=5000)
    return pts[seen >= 0.9][0], pts[seen == 0.0][0]


def test_slew_look_and_the_refusals(site_dir, tmp_path, store_kw):
    with TestClient(make_app(site_dir, tmp_path, heads="sim", **store_kw)) as c:
        body = wait_for(c, "cam1", lambda b: b["status"] is not None)
        assert body["mode"] == "idle" and body["kind"] == "sim"
        assert body["limits"]["pan_rate_deg_s"] == 90.0  # site.json's slew_limits
        assert body["status"]["time"].endswith("Z")
        listed = c.get("/api/heads", headers=AUTH).json()
        assert [h["sensor_id"] for h in listed] == ["cam1", "cam3"]  # cam2 is fixed
        r = c.put("/api/sensors/cam1/slew", headers=AUTH, json={"pan_deg": 20, "tilt_deg": -8})
        assert r.status_code == 200, r.text
        assert r.json()["mode"] == "slew"
        body = wait_for(
            c,
            "cam1",
            lambda b: not b["status"]["moving"] and abs(b["status"]["pan_deg"] - 20) < 1e-6,
        )
        assert (body["status"]["pan_deg"], body["status"]["tilt_deg"]) == pytest.approx((20, -8))
        assert body["target"] == {"pan_deg": 20.0, "tilt_deg": -8.0, "hfov_deg": None}

        visible, hidden = ground_points(site_dir)
        r = c.put(
            "/api/sensors/cam1/slew", headers=AUTH, json={"e_m": visible[0], "n_m": visible[1]}
        )
        assert r.status_code == 200, r.text
        assert r.json()["mode"] == "look"
        assert r.json()["target"]["u_m"] == pytest.approx(visible[2], abs=1e-3)
        r = c.put("/api/sensors/cam1/slew", headers=AUTH, json={"e_m": hidden[0], "n_m": hidden[1]})
        assert r.status_code == 422 and "blocked by terrain" in r.json()["detail"]
        r = c.put("/api/sensors/cam1/slew", headers=AUTH, json={"e_m": 9e6, "n_m": 0})
        assert r.status_code == 422 and "off the DEM" in r.json()["detail"]

        assert (
            c.put("/api/sensors/cam1/slew", json={"pan_deg": 1, "tilt_deg": 0}).status_code == 401
        )
        r = c.put("/api/sensors/nope/slew", headers=AUTH, json={"pan_deg": 1, "tilt_deg": 0})
        assert r.status_code == 404 and "nope" in r.json()["detail"]
        r = c.put("/api/sensors/cam2/slew", headers=AUTH, json={"pan_deg": 1, "tilt_deg": 0})
        assert r.status_code == 409 and "fixed mount" in r.json()["detail"]
        assert c.get("/api/sensors/cam2/head", headers=AUTH).status_code == 409
        for bad in (
            {"pan_deg": 1},
            {"pan_deg": 1, "tilt_deg": 0, "e_m": 3, "n_m": 4},
            {"e_m": 3},
            {"pan_deg": "NaN", "tilt_deg": 0},
            {"pan_deg": 1, "tilt_deg": 0, "hfov_deg": 0},
            {},
        ):
            r = c.put("/api/sensors/cam1/slew", headers=AUTH, json=bad)
            assert r.status_code == 422, bad
        r = c.put("/api/sensors/cam1/follow", headers=AUTH, json={"track_id": 999})
        assert r.status_code == 404 and "no live track 999" in r.json()["detail"]


def test_follow_release_and_restart(sample_site_dir, tmp_path, store_kw):
    # cam3 alone is active: cam1's detections (a fixed camera) make the track, cam3's
    # (no poses at those times: its head reports at the wall clock) are held as no_pose.
    site_dir = active_site(sample_site_dir, tmp_path / "site", {"cam3": {"active": True}})
    records = scenario_records(load_site(site_dir), "vehicle-run", 30.0, score=0.5)
    with TestClient(make_app(site_dir, tmp_path, heads="sim", **store_kw)) as c:
        post_in_time_batches(c, records)
        live = [t for t in c.get("/api/tracks", headers=AUTH).json()["tracks"] if t["live"]]
        tid = live[0]["id"]
        r = c.put("/api/sensors/cam3/follow", headers=AUTH, json={"track_id": tid})
        assert r.status_code == 200, r.text
        assert r.json()["mode"] == "follow" and r.json()["target"]["track_id"] == tid
        before = c.get("/api/sensors/cam3/head", headers=AUTH).json()
    # A restart: the journal gives the head its mode and target back.
    with TestClient(make_app(site_dir, tmp_path, heads="sim", **store_kw)) as c:
        after = wait_for(c, "cam3", lambda b: b["status"] is not None)
        assert (after["mode"], after["target"]) == (before["mode"], before["target"])
        r = c.delete("/api/sensors/cam3/follow", headers=AUTH)
        assert r.status_code == 200 and r.json()["mode"] == "idle"
    with TestClient(make_app(site_dir, tmp_path, heads="sim", **store_kw)) as c:
        assert c.get("/api/sensors/cam3/head", headers=AUTH).json()["mode"] == "idle"


def test_heads_off_and_a_site_without_active_heads(site_dir, sample_site_dir, tmp_path, store_kw):
    with TestClient(make_app(site_dir, tmp_path, heads="off", **store_kw)) as c:
        r = c.put("/api/sensors/cam1/slew", headers=AUTH, json={"pan_deg": 1, "tilt_deg": 0})
        assert r.status_code == 409
        assert c.get("/api/heads", headers=AUTH).json() == []
    # auto (the default): an active sensor without a head_adapter is its gateway's
    with TestClient(make_app(site_dir, tmp_path, **store_kw)) as c:
        assert c.get("/api/heads", headers=AUTH).json() == []
        r = c.put("/api/sensors/cam1/slew", headers=AUTH, json={"pan_deg": 1, "tilt_deg": 0})
        assert r.status_code == 409 and "not driven by this server" in r.json()["detail"]
    (tmp_path / "b").mkdir()
    with TestClient(make_app(sample_site_dir, tmp_path / "b")) as c:
        assert c.get("/api/sensors/cam1/head", headers=AUTH).status_code == 409
        assert c.get("/api/sensors/zzz/head", headers=AUTH).status_code == 404
