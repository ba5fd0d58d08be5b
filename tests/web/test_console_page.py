"""The operator console in a real browser (Chromium, headless) against a real server.

Oracles: the API itself (the page must show what the API answers for the same pixel or
time), an independent pixel-from-click computation, and RFC 7946's lon/lat order.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from web_helpers import SHOTS, TOKEN, open_console, post_until, wait_until

pytestmark = pytest.mark.timeout(600)

HEADS_JS = """() => window.demtrack.map.trails.getSource().getFeatures()
  .filter((f) => f.get('kind') === 'head')
  .map((f) => ({id: f.get('trackId'), xy: f.getGeometry().getCoordinates()}))"""


def heads(pg: Any) -> dict[int, tuple[float, float]]:
    return {h["id"]: tuple(h["xy"]) for h in pg.evaluate(HEADS_JS)}


def drawn_at_shown_time(
    pg: Any, tracks: dict[int, dict[str, Any]], timeout_s: float = 30.0
) -> tuple[float, dict[int, tuple[float, float]]]:
    """The shown time and the drawn heads, once the map has drawn that time.

    The map redraws on an animation frame after the time or the data change, later on a
    busy machine: poll until every head of a track in ``tracks`` that spans the shown
    time is drawn at its interpolated position (or ``timeout_s`` passes; the caller's
    asserts then say what differs).
    """
    last: list[Any] = []

    def drawn() -> bool:
        t = pg.evaluate("window.demtrack.timeline.now()")
        shown = heads(pg)
        last[:] = [t, shown]
        want = {k: interpolate(tr["points"], t) for k, tr in tracks.items()}
        return bool(shown) and all(
            k in shown and math.dist(shown[k], w) < 1e-6 for k, w in want.items() if w is not None
        )

    wait_until(drawn, timeout_s, 0.1, page=pg)
    return last[0], last[1]


def api_tracks(server: Any) -> list[dict[str, Any]]:
    with server.client() as c:
        return c.get("/api/tracks").json()["tracks"]


def interpolate(points: list[dict[str, Any]], t: float) -> tuple[float, float] | None:
    """Site-frame position at ``t`` on the straight segment between the bracketing points."""
    for a, b in zip(points, points[1:], strict=False):
        if a["t_s"] <= t <= b["t_s"]:
            f = 0.0 if b["t_s"] == a["t_s"] else (t - a["t_s"]) / (b["t_s"] - a["t_s"])
            return a["e_m"] + f * (b["e_m"] - a["e_m"]), a["n_m"] + f * (b["n_m"] - a["n_m"])
    return None


# --------------------------------------------------------------------------- loading
def test_page_loads_offline_without_errors(page, fed_server):
    open_console(page, fed_server)
    page.wait_for_function("window.demtrack.map.roads.getSource().getFeatures().length > 0")
    page.wait_for_timeout(500)
    rec = page.record
    assert rec.errors == [], rec.errors
    assert rec.off_loopback() == [], rec.off_loopback()
    # OpenLayers and our modules came from this server.
    assert any(u.endswith("/vendor/ol/ol.js") for u in rec.requests)
    assert any(u.endswith("/console/main.mjs") for u in rec.requests)
    # The token left the address bar (it is in sessionStorage for this tab).
    assert TOKEN not in page.url
    assert page.evaluate("sessionStorage.getItem('demtrack.token')") == TOKEN
    state = page.evaluate(
        """() => { const m = window.demtrack.map; return {
            ortho: !!m.ortho.getSource(), relief: !!m.relief.getSource(),
            sensors: m.sensors.getSource().getFeatures().length,
            coverage: m.coverage.getSource().getFeatures().length,
            imgs: [...document.querySelectorAll('.cam-img')].map((i) => i.naturalWidth),
            tracks: window.demtrack.store.tracks.size,
            layers: document.querySelectorAll('#layers input[type=checkbox]').length}; }"""
    )
    with fed_server.client() as c:
        sensors = c.get("/api/sensors").json()
    assert state["ortho"] and state["relief"]
    assert state["sensors"] == len(sensors) == state["coverage"] == 3
    assert state["imgs"] == [s["width_px"] for s in sensors]
    assert state["tracks"] == len(api_tracks(fed_server)) > 0
    assert state["layers"] >= 9
    # The cursor readout shows the API's WGS84 and DEM elevation for the point under it.
    box = page.locator("#map").bounding_box()
    x, y = int(box["x"] + box["width"] / 2), int(box["y"] + box["height"] / 2)
    page.mouse.move(x, y)
    page.wait_for_function("document.querySelector('#readout').textContent.includes('elevation')")
    e, n = page.evaluate(
        f"window.demtrack.map.map.getCoordinateFromPixel([{x - box['x']}, {y - box['y']}])"
    )
    with fed_server.client() as c:
        ans = c.get("/api/site/elevation", params={"e": round(e, 2), "n": round(n, 2)}).json()
    text = page.locator("#readout").text_content()
    assert f"{ans['lat_deg']:.6f}" in text and f"{ans['lon_deg']:.6f}" in text
    # Issue 26 item 8: the elevation in its named datum, the local up beside it.
    assert f"elevation {ans['elevation_m']:.1f} m ({ans['elevation_datum']})" in text
    assert f"local up {ans['u_m']:.1f} m" in text


# ----------------------------------------------------------------- click-to-geolocate
def test_camera_click_geolocates_like_the_api(page, fed_server):
    open_console(page, fed_server)
    view = page.locator("#cam-cam1 .cam-view")
    view.scroll_into_view_if_needed()
    bb = view.bounding_box()
    width, height = 1280, 720
    # Aim at a pixel whose ray crosses the terrain several times (tree crowns, roofs).
    xi = round(bb["x"] + (720 + 0.5) / width * bb["width"])
    yi = round(bb["y"] + (300 + 0.5) / height * bb["height"])
    u_expected = (xi - bb["x"]) / bb["width"] * width - 0.5
    v_expected = (yi - bb["y"]) / bb["height"] * height - 0.5
    page.mouse.click(xi, yi)
    page.wait_for_selector("#geo-result")
    res = page.evaluate("window.demtrack.ui.geo.result")
    u, v = res["pixel"]
    assert abs(u - u_expected) <= 0.006 and abs(v - v_expected) <= 0.006
    with fed_server.client() as c:
        first = c.post("/api/geolocate", json={"sensor": "cam1", "u": u, "v": v, "rule": "first"})
        last = c.post("/api/geolocate", json={"sensor": "cam1", "u": u, "v": v, "rule": "last"})
    first, last = first.json(), last.json()
    assert len(first["hits"]) >= 2, "the chosen pixel should cross the terrain more than once"
    assert res["hits"] == first["hits"] and res["selected"] == first["selected"]
    # The table shows every hit, the chosen one marked, with the API's numbers.
    rows = page.locator("#geo-result table.hits tr[data-e]")
    n_rows = len(first["hits"]) + (first["road"] is not None)
    assert rows.count() == n_rows
    chosen = page.locator("#geo-result tr.chosen")
    assert chosen.count() == 1
    sel = first["selected"][0]
    assert float(chosen.get_attribute("data-e")) == sel["e_m"]
    assert float(chosen.get_attribute("data-lat")) == sel["lat_deg"]
    assert f"{sel['range_m']:.1f}" in chosen.text_content()
    # On the map: a point per hit (plus the road point), the chosen one highlighted.
    on_map = page.evaluate(
        """() => window.demtrack.map.geo.getSource().getFeatures()
        .filter((f) => f.get('kind') === 'hit' || f.get('kind') === 'road')
        .map((f) => ({xy: f.getGeometry().getCoordinates(), chosen: f.get('chosen')}))"""
    )
    assert len(on_map) == n_rows
    [hl] = [f["xy"] for f in on_map if f["chosen"]]
    assert hl == [sel["e_m"], sel["n_m"]]
    # Switching the rule asks again and the answer follows.
    page.locator("input[name='geo-rule'][value='last']").check()
    page.wait_for_function(
        "window.demtrack.ui.geo && window.demtrack.ui.geo.rule === 'last'"
        " && window.demtrack.ui.geo.result"
    )
    res_last = page.evaluate("window.demtrack.ui.geo.result")
    assert res_last["selected"] == last["selected"] != first["selected"]
    # Keep it as a marker.
    page.locator("#keep-marker").click()
    markers = page.evaluate(
        "window.demtrack.map.markers.getSource().getFeatures()"
        ".map((f) => f.getGeometry().getCoordinates())"
    )
    assert markers == [[last["selected"][0]["e_m"], last["selected"][0]["n_m"]]]
    assert page.record.errors == []


# --------------------------------------------------------------------- live tracks
def test_replayed_track_appears_and_moves(page, server_factory, scenario_records):
    srv = server_factory("live")
    open_console(page, srv)
    assert heads(page) == {}
    with srv.client() as c:
        post_until(c, scenario_records, -1.0, 8.0)
        page.wait_for_function(
            "window.demtrack.store.tracks.size > 0 && window.demtrack.store.tMax >= 7",
            timeout=60_000,
        )
        _, before = drawn_at_shown_time(page, {tr["id"]: tr for tr in api_tracks(srv)})
        assert before, "a confirmed track should be drawn"
        post_until(c, scenario_records, 8.0, 16.0)
        page.wait_for_function("window.demtrack.store.tMax >= 15", timeout=60_000)
    _, after = drawn_at_shown_time(page, {tr["id"]: tr for tr in api_tracks(srv)})
    moved = [k for k in before if k in after and math.dist(before[k], after[k]) > 5.0]
    assert moved, (before, after)
    # The live head is where the API's track is at the page's time.
    t = page.evaluate("window.demtrack.timeline.now()")
    by_id = {tr["id"]: tr for tr in api_tracks(srv)}
    for k in moved:
        pts = by_id[k]["points"]
        want = interpolate(pts, t) or (pts[-1]["e_m"], pts[-1]["n_m"])
        assert math.dist(after[k], want) < 1e-6
    # Boxes of the newest fixes are drawn over the cameras with their track ids.
    n_boxes = page.evaluate(
        "[...window.demtrack.ui.cams.values()].reduce((a, p) => a + p.lastDraw[0].length, 0)"
    )
    assert n_boxes > 0
    assert page.record.errors == []
    assert page.record.off_loopback() == []


# ------------------------------------------------------------------------ timeline
def test_scrubbing_moves_the_displayed_positions(page, fed_server):
    open_console(page, fed_server)
    tracks = {tr["id"]: tr for tr in api_tracks(fed_server)}
    page.keyboard.press("Space")  # pause
    assert page.evaluate("window.demtrack.timeline.live") is False
    scrub = page.locator("#scrub").bounding_box()
    seen = []
    for frac in (0.35, 0.7):
        page.mouse.click(scrub["x"] + frac * scrub["width"], scrub["y"] + scrub["height"] / 2)
        t, shown = drawn_at_shown_time(page, tracks)
        spanning = {
            k: interpolate(tr["points"], t)
            for k, tr in tracks.items()
            if tr["points"][0]["t_s"] <= t <= tr["points"][-1]["t_s"]
        }
        assert spanning, f"no track spans t = {t}"
        for k, want in spanning.items():
            assert math.dist(shown[k], want) < 1e-6, (k, t, shown.get(k), want)
        seen.append((t, shown))
    (t1, h1), (t2, h2) = seen
    assert t2 > t1 + 3
    assert any(math.dist(h1[k], h2[k]) > 5 for k in h1.keys() & h2.keys())
    # Arrow keys step the shown time by one second; Escape clears a selection.
    page.keyboard.press("ArrowRight")
    assert page.evaluate("window.demtrack.timeline.now()") == pytest.approx(t2 + 1, abs=1e-6)
    page.locator("#track-list > div").first.click()
    page.wait_for_selector("#speed-plot")
    assert page.evaluate("window.demtrack.ui.selectedId") is not None
    page.keyboard.press("Escape")
    assert page.evaluate("window.demtrack.ui.selectedId") is None
    assert page.record.errors == []


# -------------------------------------------------------------------- trajectories
SYNOPSIS_JS = """() => {
  const u = window.demtrack.ui;
  const s = u.synopsis;
  const lines = window.demtrack.map.synopsis.getSource().getFeatures()
    .filter((f) => !f.get('end'))
    .map((f) => [f.get('trackId'), f.get('gap'), f.getGeometry().getCoordinates()]);
  return {window: s ? [s.t0, s.t1] : null,
          apiDrawn: !!s && !!u.synopsisDrawn && u.synopsisDrawn.trajs === s.trajs,
          lines, revision: window.demtrack.map.synopsis.getRevision()};
}"""


def synopsis_lines(body: dict[str, Any], cls: set[str]) -> list[tuple[Any, ...]]:
    """The API synopsis as the page should draw it: (track, gap, coordinates) per part."""
    out = []
    for tr in body["trajectories"]:
        if tr["cls"] not in cls:
            continue
        for part in tr["parts"]:
            if part["kind"] == "gap":
                coords = [
                    [part["start"]["e_m"], part["start"]["n_m"]],
                    [part["end"]["e_m"], part["end"]["n_m"]],
                ]
            else:
                coords = [[p["e_m"], p["n_m"]] for p in part["path"]]
            if len(coords) >= 2:
                out.append((tr["track_id"], part["kind"] == "gap", coords))
    return sorted(out, key=repr)


def test_trajectories_layer_draws_the_api_synopsis_and_follows_filters(page, fed_server):
    open_console(page, fed_server)
    state = wait_until(
        lambda: (s := page.evaluate(SYNOPSIS_JS))["apiDrawn"] and s, 60, 0.1, page=page
    )
    assert state, "the page never drew the server's synopsis"
    t0, t1 = state["window"]
    span = t1 - t0
    with fed_server.client() as c:
        body = c.get(
            "/api/synopsis", params={"t0": t0, "t1": t1, "step_s": max(0.5, span / 1500)}
        ).json()
    want = synopsis_lines(body, {"vehicle", "human"})
    assert want, "the scenario gave no trajectory in the window"

    def drawn() -> list[tuple[Any, ...]]:
        return sorted((tuple(x) for x in page.evaluate(SYNOPSIS_JS)["lines"]), key=repr)

    assert drawn() == want
    # Nothing changed, nothing rebuilt: the same features stay in the layer frame after frame.
    kept = page.evaluate(
        """async () => {
            const d = window.demtrack;
            const kept = d.map.synopsis.getSource().getFeatures()[0];
            for (let k = 0; k < 10; k += 1) {  // ten redraws
              d.ui.dirty = true;
              await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
            }
            return d.map.synopsis.getSource().hasFeature(kept);
        }"""
    )
    assert kept, "the trajectories were rebuilt although nothing changed"
    page.screenshot(path=str(SHOTS / "trajectories.png"))
    # A class filter rebuilds the layer without that class, and back.
    without_vehicles = synopsis_lines(body, {"human"})
    assert without_vehicles != want, "need vehicles in the window"
    box = page.locator('#filter-class input[data-class="vehicle"]')
    box.uncheck()
    wait_until(lambda: drawn() == without_vehicles, 10, 0.1, page=page)
    assert drawn() == without_vehicles
    box.check()
    wait_until(lambda: drawn() == want, 10, 0.1, page=page)
    assert drawn() == want
    # Selecting a track restyles the layer (its features stay): highlighted in its colour.
    before = page.evaluate(SYNOPSIS_JS)["revision"]
    tid = want[0][0]
    page.locator(f'#track-list div[data-track="{tid}"]').click()
    style = page.evaluate(
        """async (tid) => {
            const { SELECTED_COLOUR } = await import('/console/util.mjs');
            const m = window.demtrack.map;
            const f = m.synopsis.getSource().getFeatures()
              .find((x) => x.get('trackId') === tid && !x.get('end'));
            const styles = m.synopsisStyle(f);
            return {colour: styles[styles.length - 1].getStroke().getColor(),
                    selected: SELECTED_COLOUR, revision: m.synopsis.getRevision()};
        }""",
        tid,
    )
    assert style["colour"] == style["selected"]
    assert style["revision"] > before
    assert page.record.errors == []


# -------------------------------------------------------------------------- export
# The export menu downloads the server's files: tests/web/test_console_exports.py.


# ----------------------------------------------------------------------- reconnect
def test_reconnects_after_server_restart(page, server_factory, scenario_records):
    srv = server_factory("restart")
    open_console(page, srv)
    srv.stop()
    page.wait_for_selector("#conn[data-state='reconnecting']", timeout=30_000)
    assert page.locator("#banner").is_visible()
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "reconnecting.png"))
    srv.start()
    page.wait_for_selector("#conn[data-state='live']", timeout=60_000)
    assert not page.locator("#banner").is_visible()
    with srv.client() as c:
        post_until(c, scenario_records, -1.0, 6.0)
    page.wait_for_function("window.demtrack.store.tracks.size > 0", timeout=60_000)
    # Only the outage's own failures may be in the browser's console.
    others = [
        e
        for e in page.record.errors
        if "ERR_CONNECTION_REFUSED" not in e and "WebSocket connection" not in e
    ]
    assert others == [], others


# ------------------------------------------------------------- formats and bounds
def test_store_stays_bounded(page, fed_server):
    open_console(page, fed_server)
    sizes = page.evaluate(
        """async () => {
            const { Store, LIMITS } = await import('/console/store.mjs');
            const s = new Store();
            const pt = (t) => ({t_s: t, e_m: t, n_m: 0, u_m: 0, lat_deg: 0, lon_deg: 0, h_m: 0,
                                sensors: ['cam1'], detection_ids: [Math.round(t * 10)]});
            // 600 ended tracks, one live track growing by 100 points a message.
            for (let id = 0; id < 600; id += 1) {
              s.applyTrack({id, cls: 'human', sensors: ['cam1'], gaps: [], live: false,
                            n_points: 3, first_index: 0,
                            points: [pt(id), pt(id + 0.1), pt(id + 0.2)]});
            }
            let n = 0;
            for (let k = 0; k < 100; k += 1) {
              const pts = Array.from({length: 100}, (_, j) => pt(n + j));
              s.applyTrack({id: 9999, cls: 'vehicle', sensors: ['cam1'], gaps: [], live: true,
                            n_points: n + 100, first_index: n, points: pts});
              n += 100;
            }
            for (let k = 0; k < 2000; k += 1) {
              s.applyFix({detection_id: k, t_s: k, sensor: 'cam1', cls: 'human',
                          bbox: [0, 0, 1, 1]});
              s.applyEvent({kind: 'x', t_s: k, text: 'x', key: null});
            }
            const live = s.tracks.get(9999);
            return {tracks: s.tracks.size, live: live.points.length, base: live.base,
                    lastT: live.points[live.points.length - 1].t_s,
                    fixes: s.fixes.get('cam1').length, events: s.events.length, limits: LIMITS};
        }"""
    )
    lim = sizes["limits"]
    assert sizes["tracks"] == lim["tracks"]
    assert (
        sizes["live"] == lim["pointsPerTrack"] and sizes["base"] == 10_000 - lim["pointsPerTrack"]
    )
    assert sizes["lastT"] == 9999
    assert sizes["fixes"] == lim["fixesPerSensor"] and sizes["events"] == lim["events"]
