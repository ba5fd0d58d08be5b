"""The console's layout at 1280 x 800 and 1440 x 900 (issue 26, item 6), in Chromium.

What an operator must reach without scrolling: the Filters, Tracks and Events panes at
the top of the sidebar, every camera panel while a geolocation or a track is open below
them, every column of the hit table. Overlapping hit labels are listed in one label.
"""

from __future__ import annotations

from typing import Any

import pytest
from web_helpers import SHOTS, open_console

pytestmark = pytest.mark.timeout(300)

SIZES = [(1280, 800), (1440, 900)]


def inside(inner: dict[str, float], outer: dict[str, float], tol: float = 0.5) -> bool:
    return (
        inner["x"] >= outer["x"] - tol
        and inner["y"] >= outer["y"] - tol
        and inner["x"] + inner["width"] <= outer["x"] + outer["width"] + tol
        and inner["y"] + inner["height"] <= outer["y"] + outer["height"] + tol
    )


def rect(page: Any, sel: str) -> dict[str, float]:
    return page.evaluate(
        f"""(() => {{ const r = document.querySelector({sel!r}).getBoundingClientRect();
        return {{x: r.x, y: r.y, width: r.width, height: r.height}}; }})()"""
    )


def click_cam(page: Any, sensor: str, u: float, v: float) -> None:
    bb = page.locator(f"#cam-{sensor} .cam-view").bounding_box()
    w, h = page.evaluate(
        f"[window.demtrack.ui.cams.get('{sensor}').sensor.width_px,"
        f" window.demtrack.ui.cams.get('{sensor}').sensor.height_px]"
    )
    page.mouse.click(bb["x"] + (u + 0.5) / w * bb["width"], bb["y"] + (v + 0.5) / h * bb["height"])


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_filters_tracks_events_and_every_camera_stay_in_view(browser, fed_server, size):
    w, h = size
    context = browser.new_context(viewport={"width": w, "height": h})
    page = context.new_page()
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"uncaught: {e}"))
    try:
        open_console(page, fed_server)
        view = {"x": 0, "y": 0, "width": w, "height": h}
        left = rect(page, "#left")
        # The three panes an operator works with start in view, above the layer list.
        for pane in ("#pane-filters", "#pane-tracks", "#pane-events"):
            top = rect(page, f"{pane} > summary")
            assert inside(top, left) and inside(top, view), (pane, top)
        assert rect(page, "#pane-events > summary")["y"] < rect(page, "#pane-layers > summary")["y"]
        assert rect(page, "#pane-events #event-list")["y"] < h
        # Every timeline control sits inside the bar (none spills onto the camera column).
        bar = rect(page, "#timeline")
        assert bar["x"] + bar["width"] <= rect(page, "#cameras")["x"] + 0.5, bar
        for ctl in ("#play", "#speed", "#scrub", "#t-label", "#clock-zone", "#go-live",
                    "#syn-on", "#syn-window"):  # fmt: skip
            assert inside(rect(page, ctl), bar), (ctl, rect(page, ctl), bar)
        # Each pane folds.
        page.locator("#pane-tracks > summary").click()
        assert page.evaluate("document.querySelector('#pane-tracks').open") is False
        page.locator("#pane-tracks > summary").click()
        # Geolocate a pixel of cam1 whose ray crosses the terrain several times: the hit
        # table shows every column (sigma included) inside the detail panel.
        click_cam(page, "cam1", 720, 300)
        page.wait_for_selector("#geo-result table.hits tr[data-e]")
        page.wait_for_timeout(300)
        # (The panel scrolls down through many hits; across, every column must fit.)
        spans = page.evaluate(
            """(() => { const d = document.querySelector('#detail');
            const r = d.getBoundingClientRect();
            return {left: r.left, right: r.left + d.clientWidth, cells: [...d.querySelectorAll(
              'table.hits tr[data-e] td.sigma')].map((c) => { const q = c.getBoundingClientRect();
              return [q.left, q.right, c.textContent]; })}; })()"""
        )
        assert spans["cells"]
        for left_px, right_px, text in spans["cells"]:
            assert spans["left"] <= left_px and right_px <= spans["right"] + 0.5, (text, spans)
        assert page.evaluate(
            "(() => { const d = document.querySelector('#detail');"
            " return d.scrollWidth <= d.clientWidth; })()"
        )
        # Every camera stays on screen with the geolocation open.
        cams = page.evaluate("[...window.demtrack.ui.cams.keys()]")
        assert len(cams) >= 3
        for sid in cams:
            assert inside(rect(page, f"#cam-{sid} .cam-view"), view), sid
            assert inside(rect(page, f"#cam-{sid} .cam-view"), rect(page, "#cameras")), sid
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / f"layout_geolocation_{w}x{h}.png"))
        # ... and with a track's history open.
        page.keyboard.press("Escape")
        page.wait_for_selector("#track-list > div[data-track]")
        page.locator("#track-list > div[data-track]").first.click()
        page.wait_for_selector("#detail .detail-track")
        page.wait_for_timeout(300)
        for sid in cams:
            assert inside(rect(page, f"#cam-{sid} .cam-view"), view), sid
            assert inside(rect(page, f"#cam-{sid} .cam-view"), rect(page, "#cameras")), sid
        page.screenshot(path=str(SHOTS / f"layout_track_{w}x{h}.png"))
        assert errors == []
    finally:
        context.close()


def test_overlapping_hit_labels_are_listed_in_one(page, fed_server):
    open_console(page, fed_server)
    # Two terrain hits 1.7 m apart (under a pixel at the site's zoom) and one far away.
    labels = page.evaluate(
        """() => {
        const m = window.demtrack.map;
        const hit = (e, n, r) => ({e_m: e, n_m: n, u_m: 0, range_m: r, sigma_m: 0.5,
          lat_deg: 0, lon_deg: 0});
        const hits = [hit(10, 20, 100), hit(11.2, 21.2, 101.7), hit(120, 20, 180)];
        m.drawGeolocation({hits, selected: [hits[0]], road: null,
          ray: {origin_enu: [0, 0, 30], direction_enu: [1, 0, 0]}}, null);
        return m.hitLabels();
        }"""
    )
    assert sorted(x["label"] for x in labels) == ["1, 2", "3"], labels
    # Zoomed in far enough, they part and each has its own label.
    parted = page.evaluate(
        """() => { const m = window.demtrack.map; m.view.setResolution(0.02);
        m.view.setCenter([10.6, 20.6]); return m.hitLabels(); }"""
    )
    assert sorted(x["label"] for x in parted) == ["1", "2", "3"], parted
    assert page.record.errors == []
