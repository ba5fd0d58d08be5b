"""The visibility layers' parameter group (target height, range) in a real browser.

Oracles: ``core.visibility.target_heights`` (the target presets), the visibility endpoints asked
with
the same parameters (blind-spot outlines and centroids, viewshed polygons), the server's
own 422 message for a value it refuses, and the requests the page sent.
"""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

import pytest
from web_helpers import SHOTS, open_console

from demtrack.core.visibility.target_heights import TARGET_HEIGHT_M

pytestmark = pytest.mark.timeout(600)

HEAVY = ("coverage.png", "coverage.json", "viewshed.geojson")
LAYERS = ("visibility", "viewsheds", "blindspots")


def layer_requests(page) -> list[tuple[str, dict[str, str]]]:
    """``(endpoint, query)`` of every visibility request the page sent, in order."""
    out = []
    for url in page.record.requests:
        parts = urlsplit(url)
        name = parts.path.rsplit("/", 1)[-1]
        if name in HEAVY:
            out.append((parts.path, {k: v[-1] for k, v in parse_qs(parts.query).items()}))
    return out


def wait_ready(page) -> None:
    page.wait_for_function(
        """() => { const v = window.demtrack.ui.vis;
             return ['visibility', 'viewsheds', 'blindspots']
               .every((n) => v.status[n] === 'ready'); }""",
        timeout=180_000,
    )


def set_params(page, target: str, height: str | None, range_m: str) -> None:
    page.locator("#vis-target").select_option(target)
    if height is not None:
        page.locator("#vis-height").fill(height)
    page.locator("#vis-range").fill(range_m)
    page.locator("#vis-apply").click()


def test_target_height_and_range_reach_every_layer_and_the_drawn_outlines(page, server_factory):
    srv = server_factory("visparams")
    open_console(page, srv)
    # The presets are core.visibility.target_heights' table; a preset fixes the height field.
    options = page.evaluate(
        "[...document.querySelectorAll('#vis-target option')].map((o) => [o.value, o.text])"
    )
    assert options == [
        ["human", f"person {TARGET_HEIGHT_M['human']} m"],
        ["vehicle", f"car {TARGET_HEIGHT_M['vehicle']} m"],
        ["custom", "custom"],
    ]
    assert page.locator("#vis-height").is_disabled()
    page.locator("#vis-target").select_option("vehicle")
    assert page.locator("#vis-height").input_value() == str(TARGET_HEIGHT_M["vehicle"])
    page.locator("#vis-target").select_option("human")
    # Show the three layers with the defaults: they say which parameters they used.
    for name in LAYERS:
        page.locator(f"#layer-{name}").check()
    wait_ready(page)
    for name in LAYERS:
        used = page.locator(f"[data-used='{name}']").text_content()
        assert used == "shown: person 1.7 m · range 1000 m", (name, used)
    assert {q["target_height_m"] for _, q in layer_requests(page)} == {"1.7"}

    # A value the page refuses itself: a message, and nothing is asked.
    n = len(layer_requests(page))
    set_params(page, "custom", "-2", "500")
    status = page.locator("#vis-params-status")
    assert status.text_content() == "target height: give a number of metres, 0 or more"
    set_params(page, "custom", "2", "0")
    assert status.text_content() == "range: give a positive number of metres"
    assert len(layer_requests(page)) == n

    # A value only the server refuses: its 422 message, on one line; the layers keep theirs.
    with srv.client() as c:
        r = c.get("/api/site/coverage.json", params={"target_height_m": 2, "max_range_m": 2e5})
        assert r.status_code == 422
        refusal = r.json()["detail"]
    asked = len(layer_requests(page))
    set_params(page, "custom", "2", "200000")
    page.wait_for_function(
        "document.querySelector('#vis-params').dataset.busy === '0'"
        " && document.querySelector('#vis-params-status').textContent !== ''",
        timeout=60_000,
    )
    assert status.text_content() == f"server refused: {refusal}"
    assert "\n" not in refusal and "max_range_m" in refusal
    assert "error" in (status.get_attribute("class") or "")
    assert page.locator("[data-used='blindspots']").text_content().endswith("range 1000 m")
    refused_requests = len(layer_requests(page)) - asked
    with srv.client() as c:
        sensors = sorted(s["id"] for s in c.get("/api/sensors").json())
    assert refused_requests == 2 + len(sensors)  # the image, the summary, each viewshed

    # Two sets in a row: the first one's answers are dropped, the second one is drawn.
    first = len(layer_requests(page))
    set_params(page, "vehicle", None, "400")
    set_params(page, "custom", "3", "600")
    page.wait_for_function("document.querySelector('#vis-params').dataset.busy === '0'")
    wait_ready(page)
    assert status.text_content() == ""
    want = {"target_height_m": "3", "max_range_m": "600", "mode": "fov"}
    for name in LAYERS:
        used = page.evaluate(f"window.demtrack.ui.vis.used.{name}")
        assert used == {"target": "custom", "target_height_m": 3, "max_range_m": 600}
        assert page.locator(f"[data-used='{name}']").text_content() == (
            "shown: custom 3 m · range 600 m"
        )
    sent = layer_requests(page)[first:]
    with srv.client() as c:
        summary = c.get("/api/site/coverage.json", params=want).json()
        sheds = {
            s: c.get(f"/api/sensors/{s}/viewshed.geojson", params={**want, "frame": "enu"}).json()
            for s in sensors
        }
    paths = {p for p, q in sent if {k: q[k] for k in want} == want}
    assert paths == {
        "/api/site/coverage.png",
        "/api/site/coverage.json",
        *(f"/api/sensors/{s}/viewshed.geojson" for s in sensors),
    }
    # Every request carried one of the two sets asked for (the first ones were cut short).
    assert {(q["target_height_m"], q["max_range_m"]) for _, q in sent} <= {
        ("1.5", "400"),
        ("3", "600"),
    }
    # The drawn blind spots are the API's outlines (not boxes) and centroids.
    spots = summary["blind_spots"]
    assert spots and summary["target_height_m"] == 3 and summary["max_range_m"] == 600
    drawn = page.evaluate(
        """() => { const f = window.demtrack.ui.vis.blind.getSource().getFeatures()
                 .sort((a, b) => a.get('spot') - b.get('spot'));
             return {
               outlines: f.filter((x) => x.get('kind') === 'outline')
                 .map((x) => x.getGeometry().getCoordinates()),
               centroids: f.filter((x) => x.get('kind') === 'centroid')
                 .map((x) => x.getGeometry().getCoordinates()),
               boxes: f.filter((x) => x.get('kind') === 'bbox').length}; }"""
    )
    assert drawn["boxes"] == 0
    assert drawn["outlines"] == [b["outline_enu"] for b in spots]
    assert drawn["centroids"] == [b["centroid_enu"] for b in spots]
    assert page.locator("#blind-list > div[data-spot]").count() == len(spots)
    # ... and the viewsheds are the API's polygons for the same parameters.
    outlines = page.evaluate(
        """() => Object.fromEntries(window.demtrack.ui.vis.viewsheds.getSource().getFeatures()
             .map((f) => [f.get('sensor'), f.getGeometry().getCoordinates()]))"""
    )
    assert outlines == {s: sheds[s]["features"][0]["geometry"]["coordinates"] for s in sensors}
    # The picture: the whole site, coverage and blind-spot outlines.
    page.locator("#layer-viewsheds").uncheck()
    page.evaluate(
        """() => { const b = window.demtrack.ui.site.dem.bounds_enu;
             window.demtrack.map.view.fit(b, {padding: [10, 10, 10, 10]}); }"""
    )
    page.wait_for_timeout(600)
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "visibility_params.png"))
    # The browser itself logs each refused request; nothing else went wrong.
    refused = "the server responded with a status of 422"
    others = [e for e in page.record.errors if refused not in e]
    assert others == [] and len(page.record.errors) == refused_requests
    assert page.record.off_loopback() == []


KEY = "demtrack.visibility.params"  # visibility.mjs PARAMS_KEY
DEFAULTS = {"target": "human", "target_height_m": 1.7, "max_range_m": 1000}


def form(page) -> dict:
    """What the parameter group shows, and what the layers would ask for."""
    return page.evaluate(
        """() => ({target: document.querySelector('#vis-target').value,
                   height: document.querySelector('#vis-height').value,
                   heightOff: document.querySelector('#vis-height').disabled,
                   range: document.querySelector('#vis-range').value,
                   params: window.demtrack.ui.vis.params})"""
    )


def stored(page):
    return page.evaluate(f"localStorage.getItem('{KEY}')")


def test_parameters_survive_a_reload_and_bad_stored_values_give_the_defaults(page, server_factory):
    import json

    srv = server_factory("vispersist")
    open_console(page, srv)
    assert stored(page) is None and form(page)["params"] == DEFAULTS
    # A preset and a range, applied with every layer off (nothing is asked), are kept.
    set_params(page, "vehicle", None, "400")
    want = {"target": "vehicle", "target_height_m": TARGET_HEIGHT_M["vehicle"], "max_range_m": 400}
    assert json.loads(stored(page)) == want
    open_console(page, srv)  # reload
    assert form(page) == {"target": "vehicle", "height": str(TARGET_HEIGHT_M["vehicle"]),
                          "heightOff": True, "range": "400", "params": want}  # fmt: skip
    assert layer_requests(page) == []
    # A custom height: after a reload the form has it and the layers ask with it.
    set_params(page, "custom", "3", "600")
    open_console(page, srv)
    custom = {"target": "custom", "target_height_m": 3, "max_range_m": 600}
    assert form(page) == {"target": "custom", "height": "3", "heightOff": False,
                          "range": "600", "params": custom}  # fmt: skip
    page.locator("#layer-blindspots").check()
    page.wait_for_function("window.demtrack.ui.vis.status.blindspots === 'ready'", timeout=180_000)
    assert page.locator("[data-used='blindspots']").text_content() == (
        "shown: custom 3 m · range 600 m"
    )
    [(path, query)] = layer_requests(page)
    assert path == "/api/site/coverage.json"
    assert (query["target_height_m"], query["max_range_m"]) == ("3", "600")
    # A set the server refuses is not kept: the next load starts from the defaults.
    set_params(page, "custom", "2", "200000")
    page.wait_for_function(
        "document.querySelector('#vis-params-status').textContent.startsWith('server refused')",
        timeout=60_000,
    )
    assert stored(page) is None
    open_console(page, srv)
    assert form(page) == {"target": "human", "height": "1.7", "heightOff": True,
                          "range": "1000", "params": DEFAULTS}  # fmt: skip
    # Corrupted or ill-typed stored values: the defaults, quietly, and the value goes.
    for bad in (
        "{not json",
        "null",
        "[1, 2]",
        json.dumps({"target": "custom", "target_height_m": "3", "max_range_m": 600}),
        json.dumps({"target": "custom", "target_height_m": -1, "max_range_m": 600}),
        json.dumps({"target": "boat", "target_height_m": 1, "max_range_m": 600}),
        json.dumps({"target": "vehicle", "target_height_m": 1.5, "max_range_m": 0}),
    ):
        page.evaluate("([k, v]) => localStorage.setItem(k, v)", [KEY, bad])
        open_console(page, srv)
        got = form(page)
        assert got["params"] == DEFAULTS and got["target"] == "human", bad
        assert (got["height"], got["range"]) == ("1.7", "1000"), bad
        assert stored(page) is None, bad
    page.screenshot(path=str(SHOTS / "visibility_params_reloaded.png"))
    # The only console error: the browser's own log of the one refused request.
    assert len(page.record.errors) == 1, page.record.errors
    assert "the server responded with a status of 422" in page.record.errors[0]
    assert page.record.off_loopback() == []
