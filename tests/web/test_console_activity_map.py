"""Activity on the map: loitering circles, rendezvous links, convoys in order, all tracks of
a selected event selected.

A real server ingests the sample site's ``loitering``, ``rendezvous`` and ``convoy`` activity
cases (people dwell, two meet, three cars drive in convoy) at once; the page must
draw each episode the API stores as its kind: a circle of the episode's radius at its
place, a link between the two tracks' API positions in the middle of the meeting, the
convoy's members joined in the API's order at the API's positions. A click on an event
row selects every one of its tracks.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from web_helpers import SHOTS, open_console, post_until, wait_until

pytestmark = pytest.mark.timeout(600)


def _records(site_dir) -> list[dict[str, Any]]:
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.activity_scenarios import make_activity_scenario

    site = load_site(site_dir)
    recs = []
    for name in ("loitering", "rendezvous", "convoy"):
        sc = make_activity_scenario(site, name).scenario
        recs += [
            {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": d.score}
            for d in sc.detections
        ]
    return sorted(recs, key=lambda r: r["t"])


def _at(track: dict, t: float) -> np.ndarray:
    """The API track's (e, n) at time t, interpolated (held at its ends)."""
    ts = np.array([p["t_s"] for p in track["points"]])
    e = np.interp(t, ts, [p["e_m"] for p in track["points"]])
    n = np.interp(t, ts, [p["n_m"] for p in track["points"]])
    return np.array([e, n])


@pytest.fixture(scope="module")
def activity_server(sample_site_dir, tmp_path_factory):
    from web_helpers import Server, free_port

    srv = Server(sample_site_dir, tmp_path_factory.mktemp("act") / "c.sqlite3", free_port())
    srv.start()
    try:
        with srv.client() as c:
            post_until(c, _records(sample_site_dir), -1.0, 1e9, step_s=1.0)
        yield srv
    finally:
        srv.stop()


def test_each_activity_kind_is_drawn_as_itself(activity_server, page):
    with activity_server.client() as c:
        evs = c.get("/api/events", params={"kind": ["loitering", "rendezvous", "convoy"]}).json()
        tracks = {t["id"]: t for t in c.get("/api/tracks").json()["tracks"]}
    evs = evs["events"]
    kinds = {e["kind"] for e in evs}
    assert {"loitering", "rendezvous", "convoy"} <= kinds, kinds
    open_console(page, activity_server)
    page.select_option("#syn-window", "Infinity")  # the whole session's window
    t_end = max(e["t_end_s"] for e in evs)
    page.evaluate(f"window.demtrack.timeline.seek({t_end})")
    items = wait_until(
        lambda: (
            lambda it: (
                it
                if it and {i["kind"] for i in it} >= {"loitering", "rendezvous", "convoy"}
                else None
            )
        )(page.evaluate("window.demtrack.activity && window.demtrack.activity.items")),
        timeout_s=30,
        page=page,
    )
    assert items, "no activity drawn"
    drawn = {i["key"]: i for i in items}
    t_shown = page.evaluate("window.demtrack.timeline.now()")
    for e in evs:
        i = drawn.get(e["key"])
        assert i is not None, f"{e['kind']} {e['key']} not drawn"
        assert i["track_ids"] == e["track_ids"]
        assert i["duration_s"] == pytest.approx(e["t_end_s"] - e["t_start_s"], abs=1e-6)
        if e["kind"] == "loitering":
            assert i["centre"] == pytest.approx(e["p_enu"][:2], abs=1e-6)
            assert i["radius_m"] == pytest.approx(max(2.0, e["details"]["extent_radius_m"]))
        elif e["kind"] == "rendezvous":
            tm = (e["t_start_s"] + e["t_end_s"]) / 2
            for end, tid in zip(i["ends"], e["track_ids"], strict=True):
                assert np.hypot(*(np.array(end) - _at(tracks[tid], tm))) < 0.5
        else:  # convoy: the members in the API's order (head first) where they were
            tc = min(t_shown, e["t_end_s"])
            on_road = [k for k in e["track_ids"] if tracks[k]["points"][-1]["t_s"] >= tc]
            assert i["member_ids"] == (on_road or e["track_ids"])
            for p, tid in zip(i["members"], i["member_ids"], strict=True):
                assert np.hypot(*(np.array(p) - _at(tracks[tid], tc))) < 0.5
    # the chosen window decides what is drawn: with 1 min only the episodes reaching into
    # the last minute before the shown time, with "all" every one again
    page.select_option("#syn-window", "60")
    recent = {e["key"] for e in evs if e["t_end_s"] >= t_shown - 60}
    assert recent != {e["key"] for e in evs}, "some episode should end over a minute earlier"
    wait_until(
        lambda: {i["key"] for i in page.evaluate("window.demtrack.activity.items")} == recent,
        timeout_s=30,
        page=page,
    )
    page.select_option("#syn-window", "Infinity")
    wait_until(
        lambda: len(page.evaluate("window.demtrack.activity.items")) == len(evs),
        timeout_s=30,
        page=page,
    )
    # no purple star stands in for them any more
    stars = page.evaluate(
        "window.demtrack.map.events.getSource().getFeatures().map(f => f.get('kind'))"
    )
    assert not {"loitering", "rendezvous", "convoy"} & set(stars)
    # the labels are on a decluttering layer of their own (crowded episodes do not stack
    # their labels into a block), one per drawn episode; a long convoy's label is short
    labels = page.evaluate(
        "(() => { const l = window.demtrack.activity.labels; return {declutter:"
        " l.getDeclutter(), keys: l.getSource().getFeatures().map(f => f.get('event').key),"
        " texts: l.getSource().getFeatures().map(f => f.get('label'))}; })()"
    )
    assert labels["declutter"] == "activity"
    assert sorted(labels["keys"]) == sorted(e["key"] for e in evs)
    convoy = next(e for e in evs if e["kind"] == "convoy")
    assert f"convoy #{'→#'.join(map(str, convoy['track_ids']))} · " in " | ".join(labels["texts"])
    long_label = page.evaluate(
        "import('/console/activity_layer.mjs').then(m => m.convoyLabel("
        "{track_ids: [12, 3, 40, 7, 9], t_s: 100, t_end_s: 143.4}))"
    )
    assert long_label == "convoy #12 + 4 vehicles · 43 s"
    # in the middle of the convoy (the cars spread along the road) the chain follows the
    # road the head drove, through every member, ending at the head
    t_mid = (convoy["t_start_s"] + convoy["t_end_s"]) / 2
    page.evaluate(f"window.demtrack.timeline.seek({t_mid})")

    def chain_now() -> tuple | None:
        got = page.evaluate(
            "(() => { const a = window.demtrack.activity;"
            f" const key = {convoy['key']!r};"
            " const it = a.items.find(i => i.key === key);"
            " const f = a.layer.getSource().getFeatures()"
            "   .find(x => x.get('role') === 'chain' && x.get('event').key === key);"
            " return it && f ? [it.members, f.getGeometry().getCoordinates()] : null; })()"
        )
        # redrawn at the new time: the cars spread along the road, not piled up at the exit
        if got is None or np.ptp(np.array(got[0]), axis=0).sum() < 20.0:
            return None
        return got

    members, chain = wait_until(chain_now, timeout_s=30, page=page)
    members, line = np.array(members), np.array(chain)
    assert len(line) > len(members)  # the road's points, not a straight link per member
    assert np.allclose(line[-1], members[0])
    for m in members:
        assert np.min(np.hypot(*(line - m).T)) < 10.0

    # the kind chips: only rendezvous rows; a click on one selects both its tracks
    rdv = next(e for e in evs if e["kind"] == "rendezvous")
    for k in ("loitering", "convoy", "zone-enter", "zone-leave", "track_confirmed", "track_ended"):
        page.uncheck(f"#event-kinds input[data-kind='{k}']")
    wait_until(
        lambda: (
            page.evaluate(
                "[...document.querySelectorAll('#event-list > div')].map(d => d.dataset.kind)"
            )
            == ["rendezvous"] * sum(e["kind"] == "rendezvous" for e in evs)
        ),
        timeout_s=30,
        page=page,
    )
    texts = page.evaluate(
        "[...document.querySelectorAll('#event-list > div')].map(d => d.textContent)"
    )
    assert all("cam" not in t and "→" not in t for t in texts), texts  # no camera arrow
    page.locator(f"#event-list > div[data-key='{rdv['key']}']").click()
    sel = page.evaluate("[...window.demtrack.ui.selectedIds]")
    assert sorted(sel) == sorted(rdv["track_ids"])
    assert page.evaluate("window.demtrack.ui.selectedEvent.key") == rdv["key"]
    for tid in rdv["track_ids"]:
        assert page.locator(f"#detail .detail-event button[data-track='{tid}']").count() == 1
    wait_until(
        lambda: all(
            "sel" in (page.get_attribute(f"#track-list > div[data-track='{tid}']", "class") or "")
            for tid in rdv["track_ids"]
        ),
        timeout_s=30,
        page=page,
    )

    # the selected episode is drawn in the selection colour with its tracks' paths
    def _drawn(roles: list) -> list | None:
        return roles if "link" in roles and roles.count("path") == 2 else None

    def selected_roles() -> list:
        return page.evaluate(
            "window.demtrack.activity.layer.getSource().getFeatures()"
            ".filter(f => f.get('sel')).map(f => f.get('role'))"
        )

    # the layer redraws on the page's next frame after the click: wait for it
    roles = (
        wait_until(
            lambda: _drawn(selected_roles()),
            timeout_s=30,
            page=page,
        )
        or selected_roles()
    )
    assert "link" in roles and roles.count("path") == 2
    # and its label wins the declutter: the labels layer renders it first
    first = page.evaluate(
        "(() => { const l = window.demtrack.activity.labels;"
        " return l.getSource().getFeatures().sort(l.getRenderOrder())"
        ".map(f => f.get('sel')); })()"
    )
    assert first[0] is True and first.count(True) == 1
    page.evaluate(
        "(() => { const m = window.demtrack.map; const s = m.map.getLayers().getArray()"
        ".find(l => l.get('name') === 'activity').getSource();"
        " m.view.fit(s.getExtent(), {padding: [40, 40, 40, 40]}); })()"
    )
    page.wait_for_timeout(800)
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "activity_map.png"))
    assert not page.record.errors, page.record.errors
