"""The event list as a review tool.

A real server ingests the vehicle run and the pedestrians (up to 60 s) while one console
watches (its events arrive on the stream); a second console opens afterwards (its events
come from /api/events). Both must list exactly the API's events, in time order, worded
the same way, with clock times (UTC); no hand-off prediction is a row (the selected
track's detail shows its one prediction, the API's newest); the list follows the scrubbed
time page by page, obeys the track filter and its own kind chips, and no row is cut at
1280 px.
"""

from __future__ import annotations

from datetime import UTC, datetime
from urllib.parse import parse_qs, urlparse

import pytest
from web_helpers import SHOTS, open_console, post_until, wait_until

pytestmark = pytest.mark.timeout(600)
UNTIL_S = 60.0


def clock(t: float | None) -> str:
    """The page's clock time of t (UNIX s): HH:MM:SS.s of t rounded to the millisecond."""
    if t is None:
        return "–"
    ms = round(t * 1000)
    return datetime.fromtimestamp(ms // 1000, UTC).strftime("%H:%M:%S") + f".{ms % 1000 // 100}"


def worded(e: dict) -> str:
    """The wording of a track event body (an independent writing of events.mjs's)."""
    tid, d = e["track_ids"][0], e["details"]
    what = "ended" if e["kind"] == "track_ended" else "confirmed"
    seen = f" · {', '.join(e['sensors'])}" if e["sensors"] else ""
    return f"track {tid} ({d['cls']}) {what}{seen}"


def predicted(p: dict) -> str:
    d = p["details"]
    nxt = "" if d["next_t_s"] is None else f" at {clock(d['next_t_s'])} UTC"
    slew = " (slew)" if d["slew"] else ""
    return (
        f"{d['current']} loses it at {clock(d['exit_t_s'])} UTC; next {d['next_sensor']}{nxt}{slew}"
    )


@pytest.fixture(scope="module")
def records(sample_site_dir):
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.scenarios import make_scenario

    site = load_site(sample_site_dir)
    out = []
    for name in ("vehicle-run", "pedestrians"):
        out += [
            {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": d.score}
            for d in make_scenario(site, name).detections
            if d.t_s < UNTIL_S
        ]
    return sorted(out, key=lambda r: r["t"])


def _rows(pg) -> list[dict]:
    return pg.evaluate(
        "[...document.querySelectorAll('#event-list > div')].map(d => ({key: d.dataset.key,"
        " kind: d.dataset.kind, t: Number(d.dataset.t), cls: d.className,"
        " time: d.children[0].textContent, text: d.children[2].textContent}))"
    )


def _all_rows(pg) -> None:
    pg.evaluate(
        "(async () => { const m = await import('/console/lists.mjs');"
        " m.eventList.pageRows = 1000; })()"
    )


def test_event_list_is_a_review_tool(page, browser, server_factory, records):
    srv = server_factory("events")
    open_console(page, srv)  # this console gets the events on the stream
    with srv.client() as c:
        post_until(c, records, -1.0, UNTIL_S, step_s=1.0)
        happened = c.get("/api/events").json()["events"]
        preds = c.get("/api/events?kind=handoff").json()["events"]
    assert len(happened) >= 3 and preds, (len(happened), len(preds))
    assert "handoff" not in {e["kind"] for e in happened}
    want = sorted(happened, key=lambda e: e["t_start_s"])
    ctx = browser.new_context(viewport={"width": 1280, "height": 800})
    late = ctx.new_page()
    asked: list[str] = []
    late.on("request", lambda r: "/api/events" in r.url and asked.append(r.url))
    try:
        open_console(late, srv)  # this one loads them from /api/events
        # start-up asks for the newest ten minutes, not the first page of a long session
        with srv.client() as c:
            tracks = c.get("/api/tracks").json()["tracks"]
        t_last = max(float(p["t_s"]) for t in tracks for p in t["points"])
        first = parse_qs(urlparse(next(u for u in asked if "kind=" not in u)).query)
        assert abs(float(first["t_from"][0]) - (t_last - 600.0)) < 1.0, first
        for pg in (page, late):
            _all_rows(pg)
            pg.evaluate(f"window.demtrack.timeline.seek({UNTIL_S + 10})")
            rows = wait_until(
                lambda pg=pg: _n_rows(pg, len(want)),
                timeout_s=30,
                page=pg,
            )
            assert [r["key"] for r in rows] == [e["key"] for e in want]
            assert [r["t"] for r in rows] == [e["t_start_s"] for e in want]  # time order
            for r, e in zip(rows, want, strict=True):
                assert r["time"] == clock(e["t_start_s"])  # clock time, not seconds
                if e["kind"] in ("track_confirmed", "track_ended"):
                    assert r["text"] == worded(e)
            assert not any("handoff" == r["kind"] for r in rows)
        assert _texts(page) == _texts(late), "streamed and loaded rows read the same"

        # nothing cut at 1280 px: every row and every cell shows its whole text
        cut = late.evaluate(
            "[...document.querySelectorAll('#event-list > div, #event-list > div > span')]"
            ".filter(e => e.scrollWidth > e.clientWidth + 1).map(e => e.textContent)"
        )
        assert cut == []

        # the selected track's detail shows its one prediction (the API's newest)
        p = preds[-1]
        tid = p["track_ids"][0]
        for pg in (page, late):
            pg.evaluate(f"(async () => (await import('/console/selection.mjs')).select({tid}))()")
            cell = pg.locator("#detail td[data-prediction]")
            wait_until(
                lambda cell=cell: cell.get_attribute("data-prediction") == p["key"],
                timeout_s=20,
                page=pg,
            )
            assert cell.text_content() == predicted(p)

        # following the scrubbed time, one row per page: the page holding the shown time,
        # its row marked; turning a page stops following
        late.evaluate(
            "(async () => { const m = await import('/console/lists.mjs');"
            " m.eventList.pageRows = 1; })()"
        )
        k = len(want) // 2
        t_k = want[k]["t_start_s"]
        k_last = max(i for i, e in enumerate(want) if e["t_start_s"] <= t_k + 0.05)
        late.evaluate(f"window.demtrack.timeline.seek({t_k + 0.05})")
        wait_until(
            lambda: [r["key"] for r in _rows(late)] == [want[k_last]["key"]],
            timeout_s=10,
            page=late,
        )
        assert "now" in _rows(late)[0]["cls"]
        assert late.text_content("#event-page").startswith(f"{k_last + 1}/{len(want)}")
        late.locator("#event-prev").click()
        assert not late.is_checked("#event-follow")
        wait_until(
            lambda: [r["key"] for r in _rows(late)] == [want[k_last - 1]["key"]],
            timeout_s=10,
            page=late,
        )

        # the track filter reaches the list: only that track's events (the API's answer)
        _all_rows(late)
        late.check("#event-follow")
        late.evaluate(f"window.demtrack.timeline.seek({UNTIL_S + 10})")
        one = want[0]["track_ids"][0]
        with srv.client() as c:
            mine = c.get(f"/api/events?track={one}").json()["events"]
        late.fill("#filter-track", str(one))
        late.dispatch_event("#filter-track", "input")
        late.dispatch_event("#filter-track", "change")
        wait_until(
            lambda: [r["key"] for r in _rows(late)] == [e["key"] for e in mine],
            timeout_s=10,
            page=late,
        )
        # and the kind chips: without "confirmed" none of its rows
        late.uncheck("#event-kinds input[data-kind='track_confirmed']")
        wait_until(
            lambda: all(r["kind"] != "track_confirmed" for r in _rows(late)),
            timeout_s=10,
            page=late,
        )
        late.fill("#filter-track", "")
        late.dispatch_event("#filter-track", "input")
        late.dispatch_event("#filter-track", "change")
        late.check("#event-kinds input[data-kind='track_confirmed']")
        late.wait_for_timeout(600)
        SHOTS.mkdir(parents=True, exist_ok=True)
        late.screenshot(path=str(SHOTS / "event_list.png"))
        assert page.record.errors == []
    finally:
        ctx.close()


def _n_rows(pg, n: int) -> list[dict] | None:
    rows = _rows(pg)
    return rows if len(rows) == n else None


def _texts(pg) -> dict[str, str]:
    return {r["key"]: r["text"] for r in _rows(pg)}
