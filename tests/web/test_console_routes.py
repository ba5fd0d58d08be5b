"""The console's server side without a browser: static files, config, the elevation readout."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from starlette.testclient import TestClient
from web_helpers import AUTH, OL_JS, TOKEN

from demtrack.core.site.folder import load_site
from demtrack.server.app import create_app


@pytest.fixture(scope="module")
def client(sample_site_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    db = tmp_path_factory.mktemp("routes") / "console.sqlite3"
    app = create_app(site=sample_site_dir, db_path=db, token=TOKEN, warm_up=False)
    with TestClient(app) as c:
        yield c


def test_page_modules_and_openlayers_are_served_with_their_types(client):
    page = client.get("/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert 'src="/vendor/ol/ol.js"' in page.text and "/console/main.mjs" in page.text
    js = client.get("/console/main.mjs")
    assert js.status_code == 200 and js.headers["content-type"].startswith("text/javascript")
    assert client.get("/console/style.css").headers["content-type"].startswith("text/css")
    ol = client.get("/vendor/ol/ol.js")
    assert ol.status_code == 200 and len(ol.content) == OL_JS.stat().st_size
    assert client.get("/vendor/ol/ol.css").status_code == 200


@pytest.mark.parametrize(
    "path",
    [
        "/console/../index.html",
        "/console/%2e%2e/index.html",
        "/console/..%2Findex.html",
        "/console/..%2F..%2Fpyproject.toml",
        "/console/",
        "/console/nope.mjs",
        "/console/a//b.mjs",
        "/console/..\\index.html",
        "/vendor/ol/package.json",
        "/vendor/ol/..%2F..%2Fpackage.json",
    ],
)
def test_nothing_outside_the_console_folders_is_served(client, path):
    resp = client.get(path)
    assert resp.status_code == 404, (path, resp.text[:200])


def test_config_names_the_optional_endpoints_this_server_has(client):
    cfg = client.get("/console-config.json").json()
    paths = set(client.app.openapi()["paths"])
    assert set(cfg["endpoints"]) == {"events", "synopsis", "export"}
    assert cfg["endpoints"]["synopsis"] == ("/api/synopsis" in paths)
    assert cfg["endpoints"]["events"] == ("/api/events" in paths)
    assert cfg["viser_url"] is None or cfg["viser_url"].startswith("http")


def test_elevation_readout_is_the_dem_surface_and_the_frame(client, sample_site_dir):
    site = load_site(sample_site_dir)
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = site.dem.grid.bounds
    for e, n in rng.uniform([x0, y0], [x1, y1], size=(5, 2)):
        got = client.get("/api/site/elevation", params={"e": e, "n": n}, headers=AUTH).json()
        z = float(site.dem.sample(np.array([e]), np.array([n]))[0])
        lat, lon, h = site.frame.to_geodetic(e, n, z)
        assert got["u_m"] == pytest.approx(z, abs=1e-9)
        assert (got["lat_deg"], got["lon_deg"], got["h_m"]) == pytest.approx(
            (float(lat), float(lon), float(h)), abs=1e-9
        )
    off = client.get("/api/site/elevation", params={"e": x1 + 500, "n": 0}, headers=AUTH).json()
    assert off["u_m"] is None and np.isfinite(off["lat_deg"])


@pytest.mark.parametrize("e, n", [("nan", "0"), ("inf", "0"), ("1e9", "0"), ("x", "1")])
def test_elevation_rejects_bad_points(client, e, n):
    resp = client.get("/api/site/elevation", params={"e": e, "n": n}, headers=AUTH)
    assert resp.status_code == 422 and resp.json()["detail"]


def test_elevation_needs_the_token_like_every_read(client):
    assert client.get("/api/site/elevation", params={"e": 0, "n": 0}).status_code == 401


def test_detections_of_a_time_window_are_those_stored_then(client):
    """The camera panels' boxes of a past moment: the window query against the id listing."""
    rng = np.random.default_rng(0)
    recs = []
    for sensor, t0 in (("cam1", 0.0), ("cam3", 0.05), ("cam2", 0.1)):
        for k in range(40):
            u, v = rng.uniform(100, 1000), rng.uniform(100, 600)
            recs.append({"t": round(t0 + 0.25 * k, 3), "sensor": sensor, "class": "human",
                         "bbox": [u - 8, v - 30, u + 8, v]})  # fmt: skip
    resp = client.post("/api/detections", json={"detections": recs}, headers=AUTH)
    assert resp.status_code == 200 and resp.json()["skipped"] == 0
    listed = client.get("/api/detections", params={"limit": 10_000}, headers=AUTH).json()
    mine = [d for d in listed if d["t"] <= 10.0 and d["class"] == "human"]
    for t_from, t_to, sensors in [(2.0, 2.6, None), (2.05, 2.05, None), (0.0, 9.9, ["cam3"]),
                                  (-5.0, 0.0, ["cam1", "cam2"]), (3.01, 3.04, None)]:  # fmt: skip
        params: dict = {"t_from": t_from, "t_to": t_to}
        if sensors:
            params["sensor"] = sensors
        got = client.get("/api/detections", params=params, headers=AUTH).json()
        want = [
            d
            for d in mine
            if t_from <= d["t"] <= t_to and (sensors is None or d["sensor"] in sensors)
        ]
        assert got == sorted(want, key=lambda d: (d["t"], d["id"])), (t_from, t_to, sensors)
    # Paging inside a window, and one-sided windows.
    page = client.get("/api/detections", params={"t_from": 1.0, "limit": 3}, headers=AUTH).json()
    assert [d["t"] for d in page] == sorted(d["t"] for d in mine if d["t"] >= 1.0)[:3]
    early = client.get("/api/detections", params={"t_to": 0.05}, headers=AUTH).json()
    assert {(d["sensor"], d["t"]) for d in early} >= {("cam1", 0.0), ("cam3", 0.05)}
    assert all(d["t"] <= 0.05 for d in early)


@pytest.mark.parametrize(
    "params, code",
    [({"t_from": 3, "t_to": 2}, 422), ({"t_from": "nan"}, 422), ({"sensor": "nope"}, 404)],
)
def test_detections_window_rejects_bad_queries(client, params, code):
    resp = client.get("/api/detections", params=params, headers=AUTH)
    assert resp.status_code == code and resp.json()["detail"]
