"""The camera panels of active heads: follow the selected track, release, look at a map point.

A real ``demtrack serve`` on a copy of the sample site whose cam1 and cam2 are active
(simulated) heads (cam3, fixed, makes the track: the active cameras' detections of the
scenario have no poses at their times, as their heads report on the wall clock);
Chromium clicks the buttons and the map, and the server's ``GET /api/sensors/{id}/head``
must show what the click asked for.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from web_helpers import SHOTS, Server, free_port, open_console, post_records, wait_until

from demtrack.core.site.folder import load_site
from demtrack.core.visibility.viewshed import target_visible_fraction

pytestmark = pytest.mark.timeout(300)


def active_copy(sample_site_dir, dest):
    shutil.copytree(sample_site_dir, dest, ignore=shutil.ignore_patterns("*.npy", "*.sqlite3*"))
    doc = json.loads((dest / "site.json").read_text("utf-8"))
    for s in doc["sensors"]:
        s["active"] = s["id"] in ("cam1", "cam2")
    (dest / "site.json").write_text(json.dumps(doc), "utf-8")
    return dest


def head(srv, sid):
    with srv.client() as c:
        return c.get(f"/api/sensors/{sid}/head").json()


def test_follow_release_and_look_here(page, sample_site_dir, tmp_path):
    from demtrack.samplesite.scenarios import make_scenario

    site_dir = active_copy(sample_site_dir, tmp_path / "site")
    site = load_site(site_dir)
    recs = [
        {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": 0.5}
        for d in make_scenario(site, "vehicle-run").detections
        if d.t_s < 30.0
    ]
    srv = Server(site_dir, tmp_path / "console.sqlite3", free_port()).start()
    try:
        with srv.client() as c:
            for k in range(0, len(recs), 200):
                post_records(c, recs[k : k + 200], f"ptz-{k}")
        open_console(page, srv)
        page.wait_for_selector("body[data-ptz='2']")
        assert page.locator("#cam-cam3 .ptz").count() == 0  # a fixed camera: no strip
        strip_follow = page.locator("#cam-cam1 .ptz")
        assert "idle" in strip_follow.locator(".ptz-mode").inner_text()

        # Follow: select the live track in the list, press the button.
        row = page.locator("#track-list > div[data-track]", has_text="●").first
        tid = int(row.get_attribute("data-track"))
        row.click()
        strip_follow.locator(".ptz-follow").click()
        body = wait_until(lambda: (b := head(srv, "cam1"))["mode"] == "follow" and b, 20, page=page)
        assert body and body["target"]["track_id"] == tid
        wait_until(
            lambda: f"track {tid}" in strip_follow.locator(".ptz-mode").inner_text(), 10, page=page
        )
        assert f"following track {tid}" in strip_follow.locator(".ptz-mode").inner_text()
        assert "pan " in strip_follow.locator(".ptz-pose").inner_text()

        # Release.
        strip_follow.locator(".ptz-release").click()
        assert wait_until(lambda: head(srv, "cam1")["mode"] == "idle", 20, page=page)

        # Look here: press it on cam2, click a ground point cam2 can see on the map.
        cam = site.sensor("cam2").camera
        xy = np.stack(np.meshgrid(np.arange(-100, 100, 10.0), np.arange(-100, 100, 10.0)), -1)
        xy = xy.reshape(-1, 2)
        z = site.dem.sample(xy[:, 0], xy[:, 1])
        pts = np.column_stack([xy, z])[np.isfinite(z)]
        seen = target_visible_fraction(site.dem, cam, pts, 1.5, in_view=False, max_range_m=5000)
        e, n = pts[seen >= 1.0][0][:2]
        strip_look = page.locator("#cam-cam2 .ptz")
        strip_look.locator(".ptz-look").click()
        px = page.evaluate(f"window.demtrack.map.map.getPixelFromCoordinate([{e}, {n}])")
        box = page.locator("#map").bounding_box()
        page.mouse.click(box["x"] + px[0], box["y"] + px[1])
        body = wait_until(lambda: (b := head(srv, "cam2"))["mode"] == "look" and b, 20, page=page)
        assert body, (strip_look.inner_text(), head(srv, "cam2"))
        res = page.evaluate("window.demtrack.map.map.getView().getResolution()")
        assert abs(body["target"]["e_m"] - e) < 2 * res + 0.01
        assert abs(body["target"]["n_m"] - n) < 2 * res + 0.01
        wait_until(
            lambda: "looking at" in strip_look.locator(".ptz-mode").inner_text(), 10, page=page
        )
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.locator("#cameras").screenshot(path=str(SHOTS / "ptz_camera_panels.png"))
        assert not page.record.errors, page.record.errors
    finally:
        srv.stop()
