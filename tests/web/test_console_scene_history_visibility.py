"""The console's 3D follow, stored camera boxes and visibility layers, in a real browser.

Oracles: the ingested scenario records themselves (which boxes exist at a time), the API's
detection listing in id order and its tracks' detection ids (box ids and track labels),
the visibility endpoints (feature counts, coordinates, legend colours) and the 3D scene's
own report of where its viser clients look (a real viser client in the 3D tab's iframe).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest
from web_helpers import AUTH, SHOTS, Server, free_port, open_console, post_until, wait_until

pytestmark = pytest.mark.timeout(600)

WINDOW_S = 0.6  # cameras.mjs BOX_WINDOW_S
LIFT_M = 0.4  # the 3D scene draws tracks this far above their points


def poll(fn, timeout_s: float = 60.0, every_s: float = 0.25, seen: Any = None) -> Any:
    """``fn()`` until it returns something truthy (or fail after ``timeout_s``).

    ``seen``: a list ``fn`` keeps what it last looked at in, shown when it fails.
    """
    out = wait_until(fn, timeout_s, every_s)
    assert out, f"timed out; last seen: {seen[-1] if seen else None}"
    return out


# ------------------------------------------------------------------- 3D follows
def test_selecting_a_track_makes_the_3d_cameras_follow_it(
    page, browser, sample_site_dir: Path, tmp_path: Path, scenario_records
):
    """Two operators' pages follow two tracks: each page's viser client looks at its own."""
    srv = Server(
        sample_site_dir,
        tmp_path / "scene.sqlite3",
        free_port(),
        extra_args=("--3d", "--viser-port", "0"),
    ).start()
    other = browser.new_context(viewport={"width": 1280, "height": 800})
    page2 = other.new_page()
    errors2: list[str] = []
    page2.on("console", lambda m: errors2.append(m.text) if m.type == "error" else None)
    page2.on("pageerror", lambda e: errors2.append(f"uncaught: {e}"))
    try:
        with srv.client() as c:
            post_until(c, scenario_records, -1.0, 16.0)
            open_console(page, srv)
            open_console(page2, srv)
            assert page.evaluate("window.demtrack.ui.viserUrl").startswith("http://127.0.0.1:")
            s1, s2 = (p.evaluate("window.demtrack.ui.follow3d.session") for p in (page, page2))
            assert re.fullmatch("[0-9a-f]{32}", s1) and s1 != s2
            page.wait_for_selector("#track-list > div[data-track='1']")
            with page.expect_request(
                lambda r: r.method == "PUT" and r.url.endswith("/api/scene3d/follow")
            ) as req:
                page.locator("#track-list > div[data-track='1']").click()
            assert req.value.post_data_json == {"track_id": 1, "session": s1}
            assert req.value.headers["authorization"] == AUTH["Authorization"]
            page.wait_for_function(
                "document.querySelector('#follow-3d:not(.hidden)')?.textContent"
                ".includes('follow track #1 ·')"
            )
            # The second operator picks another track.
            row2 = "#track-list > div[data-track]:not([data-track='1'])"
            page2.wait_for_selector(row2)
            t2 = int(page2.locator(row2).first.get_attribute("data-track"))
            with page2.expect_request(
                lambda r: r.method == "PUT" and r.url.endswith("/api/scene3d/follow")
            ) as req2:
                page2.locator(row2).first.click()
            assert req2.value.post_data_json == {"track_id": t2, "session": s2}

            def newest(tid: int) -> list[float]:
                p = c.get(f"/api/tracks/{tid}").json()["tracks"][0]["points"][-1]
                return [p["e_m"], p["n_m"], p["u_m"] + LIFT_M]

            seen: list[Any] = []

            def looking_at(session: str, tid: int, want: list[float]) -> bool:
                st = c.get("/api/scene3d/follow", params={"session": session}).json()
                seen.append({"want": want, "state": st})
                del seen[:-1]
                return (
                    st["track_id"] == tid
                    and math.dist(st["look_at_enu"], want) < 1e-6
                    and bool(st["clients"])
                    and all(
                        k["session"] == session
                        and k["track_id"] == tid
                        and math.dist(k["look_at_enu"], want) < 1e-3
                        for k in st["clients"]
                    )
                )

            # The 3D tab: viser's own client in the iframe connects on its page's session
            # and starts at that page's track head. (On this machine WebGL is software-
            # rendered and shares the page's thread, so each page goes back to the map
            # while its 3D view is not looked at.)
            for pg, sid in ((page, s1), (page2, s2)):
                pg.locator("#tab-3d").click()
                src = pg.evaluate("document.querySelector('#viser').src")
                assert src.startswith(pg.evaluate("window.demtrack.ui.viserUrl") + "?websocket=")
                assert src.endswith(f"%2Ffollow%2F{sid}")
            first = {1: newest(1), t2: newest(t2)}
            assert math.dist(first[1], first[t2]) > 1.0
            poll(lambda: looking_at(s1, 1, first[1]), 120, seen=seen)
            poll(lambda: looking_at(s2, t2, first[t2]), 120, seen=seen)
            page.locator("#tab-map").click()
            page2.locator("#tab-map").click()
            everyone = c.get("/api/scene3d/follow").json()
            assert everyone["track_id"] is None  # no broadcast choice
            assert sorted(k["session"] for k in everyone["clients"]) == sorted([s1, s2])
            # New fixes arrive: each page's cameras follow its own track's new head.
            post_until(c, scenario_records, 16.0, 24.0)
            second = newest(1)
            assert math.dist(first[1], second) > 5.0
            poll(lambda: looking_at(s1, 1, second), seen=seen)
            poll(lambda: looking_at(s2, t2, newest(t2)), seen=seen)
            cam = c.get("/api/scene3d/follow", params={"session": s1}).json()["clients"][0]
            assert cam["position_enu"][2] > second[2] + 10.0  # above the head, not on it
            page.locator("#tab-3d").click()
            page.wait_for_timeout(3000)  # let the client draw the new view
            SHOTS.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(SHOTS / "follow_3d.png"))
            page.locator("#tab-map").click()
            # Esc clears the first page's selection: its scene stops, the other goes on.
            # The first try is dropped on the way (as a reset connection would be): the
            # page sends it again by itself.
            dropped: list[str] = []

            def drop_once(route: Any) -> None:
                if not dropped:
                    dropped.append(route.request.post_data or "")
                    route.abort("connectionreset")
                else:
                    route.continue_()

            page.route("**/api/scene3d/follow", drop_once)
            with page.expect_response(
                lambda r: r.request.method == "PUT" and r.url.endswith("/api/scene3d/follow"),
                timeout=60_000,
            ) as resp:
                page.keyboard.press("Escape")
            assert resp.value.ok, (resp.value.status, resp.value.text())
            assert resp.value.request.post_data_json == {"track_id": None, "session": s1}
            assert len(dropped) == 1 and '"track_id":null' in dropped[0]
            page.wait_for_function("!window.demtrack.ui.follow3d.inFlight")
            follow = page.evaluate("({r: window.demtrack.ui.follow3d.retries, "
                                   "e: window.demtrack.ui.follow3d.error})")  # fmt: skip
            assert follow == {"r": 1, "e": None}, follow
            assert c.get("/api/scene3d/follow", params={"session": s1}).json()["track_id"] is None
            page.unroute("**/api/scene3d/follow")
            errors = page.record.errors
            errors[:] = [e for e in errors if "ERR_CONNECTION_RESET" not in e]  # the drop
            assert "hidden" in page.locator("#follow-3d").get_attribute("class")
            assert c.get("/api/scene3d/follow", params={"session": s2}).json()["track_id"] == t2
        assert page.record.errors == [], page.record.errors
        assert errors2 == [], errors2
        assert page.record.off_loopback() == []
    finally:
        other.close()
        srv.stop()


# ----------------------------------------------------------- boxes of the past
def stored_ids(server: Any) -> dict[tuple[str, float, tuple[float, ...]], int]:
    """``(sensor, t, bbox) -> id`` from the plain id-order listing."""
    out: dict[tuple[str, float, tuple[float, ...]], int] = {}
    after = 0
    with server.client() as c:
        while rows := c.get("/api/detections", params={"after_id": after, "limit": 5000}).json():
            for d in rows:
                out[(d["sensor"], d["t"], tuple(d["bbox"]))] = d["id"]
            after = rows[-1]["id"]
    return out


def test_scrubbing_far_back_shows_the_stored_boxes_of_that_time(page, fed_server, scenario_records):
    open_console(page, fed_server)
    page.keyboard.press("Space")  # pause
    oldest = page.evaluate(
        """() => Object.fromEntries([...window.demtrack.store.fixes.entries()]
             .map(([s, l]) => [s, l.length ? l[0].t_s : null]))"""
    )
    ids = stored_ids(fed_server)
    with fed_server.client() as c:
        by_det = {
            d: tr["id"]
            for tr in c.get("/api/tracks").json()["tracks"]
            for p in tr["points"]
            for d in p["detection_ids"]
        }

    def check(t: float) -> int:
        page.wait_for_function(
            f"""() => {{ const p = window.demtrack.ui.past;
                 return p.covers({t}, {WINDOW_S}) && !p.inFlight
                   && window.demtrack.timeline.now() === {t}; }}"""
        )
        # the page's next animation frame draws that state (its frame handler runs first)
        page.evaluate(
            "() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)))"
        )
        panels = page.evaluate(
            """() => [...window.demtrack.ui.cams.entries()].map(([sid, p]) => ({
                 sid, boxes: p.root.dataset.boxes, drawn: p.drawn,
                 w: p.canvas.width, h: p.canvas.height}))"""
        )
        n = 0
        for panel in panels:
            sid = panel["sid"]
            want = [
                r for r in scenario_records if r["sensor"] == sid and t - WINDOW_S < r["t"] <= t
            ]
            if oldest.get(sid) is not None and oldest[sid] <= t - WINDOW_S:
                assert panel["boxes"] == "recent"  # the store's own fixes cover it
                continue
            assert panel["boxes"] == "stored", (sid, t, oldest)
            drawn = panel["drawn"]
            assert sorted(d["bbox"] for d in drawn) == sorted(r["bbox"] for r in want), (sid, t)
            want_ids = sorted(ids[(sid, r["t"], tuple(r["bbox"]))] for r in want)
            assert sorted(d["detection_id"] for d in drawn) == want_ids
            for d in drawn:
                did = d["detection_id"]
                assert d["label"] == (f"#{by_det[did]}" if did in by_det else "·")
            n += len(drawn)
        return n

    # Scrub (mouse on the slider) to early in the session, before the store's fixes.
    scrub = page.locator("#scrub").bounding_box()
    page.mouse.click(scrub["x"] + 0.1 * scrub["width"], scrub["y"] + scrub["height"] / 2)
    t = page.evaluate("window.demtrack.timeline.now()")
    assert any(v is None or v > t for v in oldest.values()), (t, oldest)
    n = check(t)
    assert n > 0, "the scrubbed time should show boxes"
    labels = page.evaluate(
        "[...window.demtrack.ui.cams.values()].flatMap((p) => p.drawn.map((d) => d.label))"
    )
    assert any(lab.startswith("#") for lab in labels), labels
    # The arrow keys step through the past: the boxes follow (from the same chunk).
    requests = page.evaluate("window.demtrack.ui.past.requests")
    page.keyboard.press("ArrowRight")
    t2 = page.evaluate("window.demtrack.timeline.now()")
    assert t2 == pytest.approx(t + 1.0, abs=1e-9)
    assert check(t2) > 0
    assert page.evaluate("window.demtrack.ui.past.requests") == requests
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "stored_boxes.png"))
    # Back to live: the panels show the stream's recent fixes again.
    page.locator("#go-live").click()
    page.wait_for_function(
        "[...window.demtrack.ui.cams.values()].every((p) => p.root.dataset.boxes === 'recent')"
    )
    assert page.record.errors == [], page.record.errors


# ------------------------------------------------------------ visibility layers
def test_visibility_layers_load_when_shown_and_match_the_api(page, fed_server):
    open_console(page, fed_server)
    names = page.evaluate(
        "[...document.querySelectorAll('#layers input[data-layer]')].map((b) => b.dataset.layer)"
    )
    assert {"visibility", "viewsheds", "blindspots"} <= set(names)
    for name in ("visibility", "viewsheds", "blindspots"):
        assert not page.locator(f"#layer-{name}").is_checked()  # off by default
    # Nothing of them was fetched at load (the page stays fast).
    heavy = ("coverage.png", "coverage.json", "viewshed.geojson")
    assert not [u for u in page.record.requests if any(h in u for h in heavy)]
    with fed_server.client() as c:
        summary = c.get("/api/site/coverage.json").json()
        sensors = sorted(s["id"] for s in c.get("/api/sensors").json())
        sheds = {
            s: c.get(f"/api/sensors/{s}/viewshed.geojson", params={"frame": "enu"}).json()
            for s in sensors
        }
    # Coverage: the raster over the DEM grid, the legend from coverage.json.
    page.locator("#layer-visibility").check()
    page.wait_for_function("window.demtrack.ui.vis.status.visibility === 'ready'", timeout=120_000)
    cov = page.evaluate(
        """() => { const l = window.demtrack.ui.vis.coverage; const s = l.getSource();
             return {visible: l.getVisible(), extent: s.getImageExtent(),
                     swatches: [...document.querySelectorAll('#coverage-legend [data-count]')]
                       .map((e) => [Number(e.dataset.count),
                                    getComputedStyle(e.querySelector('.swatch')).backgroundColor])};
        }"""
    )
    with fed_server.client() as c:
        site = c.get("/api/site").json()
    assert cov["visible"] and cov["extent"] == site["dem"]["bounds_enu"]
    assert [k for k, _ in cov["swatches"]] == [e["count"] for e in summary["legend"]]
    for (_, css), e in zip(cov["swatches"], summary["legend"], strict=True):
        *rgb, a = (float(x) for x in re.findall(r"[\d.]+", css))
        assert rgb == e["rgba"][:3] and round(a * 255) == e["rgba"][3], (css, e)
    # Viewsheds: one outline per sensor, the API's polygons.
    page.locator("#layer-viewsheds").check()
    page.wait_for_function("window.demtrack.ui.vis.status.viewsheds === 'ready'", timeout=120_000)
    drawn = page.evaluate(
        """() => window.demtrack.ui.vis.viewsheds.getSource().getFeatures().map((f) => ({
             sensor: f.get('sensor'), coords: f.getGeometry().getCoordinates()}))"""
    )
    want = [f for s in sensors for f in sheds[s]["features"]]
    assert len(drawn) == len(want) == len(sensors)
    for d in drawn:
        [f] = sheds[d["sensor"]]["features"]
        assert d["coords"] == f["geometry"]["coordinates"]
    # Blind spots: on the map and listed, largest first; a click centres the map on one.
    page.locator("#layer-blindspots").check()
    page.wait_for_function("window.demtrack.ui.vis.status.blindspots === 'ready'", timeout=120_000)
    spots = summary["blind_spots"]
    assert spots, "the sample site has blind spots"
    centroids = page.evaluate(
        """() => window.demtrack.ui.vis.blind.getSource().getFeatures()
             .filter((f) => f.get('kind') === 'centroid')
             .sort((a, b) => a.get('spot') - b.get('spot'))
             .map((f) => f.getGeometry().getCoordinates())"""
    )
    assert centroids == [b["centroid_enu"] for b in spots]
    rows = page.locator("#blind-list > div[data-spot]")
    assert rows.count() == len(spots)
    area = math.floor(spots[0]["area_m2"] + 0.5)  # toFixed(0) rounds half up
    assert f"{area} m²" in rows.first.text_content()
    rows.nth(1).click()
    centre = page.evaluate("window.demtrack.map.view.getCenter()")
    assert centre == pytest.approx(spots[1]["centroid_enu"], abs=1e-6)
    # The opacity slider acts on the coverage layer only.
    page.locator("#coverage-opacity").fill("0.6")
    assert page.evaluate("window.demtrack.ui.vis.coverage.getOpacity()") == pytest.approx(0.6)
    # Keyboard still works with a layer checkbox focused; the checkbox keeps its state.
    running = "window.demtrack.timeline.live || window.demtrack.timeline.playing"
    page.locator("#layer-blindspots").focus()
    before = page.evaluate(running)
    page.keyboard.press("Space")
    assert page.evaluate(running) is (not before)
    assert page.locator("#layer-blindspots").is_checked()
    # Off again: hidden, and the data stays (no second request when shown again).
    n_req = len([u for u in page.record.requests if "viewshed.geojson" in u])
    page.locator("#layer-viewsheds").uncheck()
    assert page.evaluate("window.demtrack.ui.vis.viewsheds.getVisible()") is False
    page.locator("#layer-viewsheds").check()
    assert len([u for u in page.record.requests if "viewshed.geojson" in u]) == n_req
    # The picture: coverage and blind spots over the whole site, a track selected.
    page.locator("#layer-viewsheds").uncheck()
    page.evaluate(
        """() => { const b = window.demtrack.ui.site.dem.bounds_enu;
             window.demtrack.map.view.fit(b, {padding: [10, 10, 10, 10]}); }"""
    )
    page.locator("#track-list > div").first.click()
    page.wait_for_selector("#speed-plot")
    page.wait_for_timeout(600)
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "visibility_layers.png"))
    assert page.record.errors == [], page.record.errors
    assert page.record.off_loopback() == []
