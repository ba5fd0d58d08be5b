"""Events as a review list: what happened apart from hand-off predictions, filters, pages.

A hand-off prediction is an annotation on a live track, not an event: one stored row per
track, replaced as the prediction changes (the same ``key`` on every stream message), and
``/api/events`` lists it only when asked for (``kind=handoff``).
"""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app, post_in_time_batches

from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.live_events import HANDOFF_HOLD, LiveEventParams
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def records(sample_site_dir):
    """The whole vehicle run (it crosses the cameras' boundaries), as records."""
    sc = make_scenario(load_site(sample_site_dir), "vehicle-run")
    return [
        {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": d.score}
        for d in sc.detections
    ]


def test_a_prediction_is_one_row_per_track_updated_in_place(sample_site_dir, records, tmp_path):
    site = load_site(sample_site_dir)
    msgs: list[dict] = []
    p = Pipeline(
        site, Store(tmp_path / "h.sqlite3"), "kalman", msgs.extend, events=LiveEventParams()
    )
    p.start()
    k = 0
    while k < len(records):  # batches of 0.5 s, as a gateway posts them
        j = k
        while j < len(records) and records[j]["t"] < records[k]["t"] + 0.5:
            j += 1
        p.ingest(records[k:j])
        k = j
    streamed = [m["event"] for m in msgs if m["type"] == "event" and m["kind"] == "handoff"]
    assert len(streamed) >= 2, "the vehicle run's prediction changes as it drives on"
    stored = p.store.activity(kinds=["handoff"])
    per_track: dict[int, list] = {}
    for h in stored:
        per_track.setdefault(h["track_ids"][0], []).append(h)
    assert all(len(v) == 1 for v in per_track.values()), "one prediction row per track"
    for h in streamed:  # every message names the track's one row
        assert h["key"] == f"handoff:{h['track_ids'][0]}"
    newest = {h["track_ids"][0]: h for h in streamed}  # the last message per track wins
    assert {tid: v[0]["details"] for tid, v in per_track.items()} == {
        tid: h["details"] for tid, h in newest.items()
    }
    assert len(streamed) > len(per_track), "a changed prediction replaced the track's row"
    # no flip-flop: a changed next sensor under the same current one has held HANDOFF_HOLD
    # evaluations (1 s apart) before it is announced
    for a, b in zip(streamed, streamed[1:], strict=False):
        if a["track_ids"] == b["track_ids"] and a["sensors"][0] == b["sensors"][0]:
            assert b["t_start_s"] - a["t_start_s"] >= HANDOFF_HOLD - 1 - 1e-6


@pytest.fixture(scope="module")
def fed(sample_site_dir, records, tmp_path_factory, module_store_kw):
    app = make_app(sample_site_dir, tmp_path_factory.mktemp("ev"), **module_store_kw)
    with TestClient(app) as c:
        post_in_time_batches(c, records)
        yield c


def test_events_leave_predictions_out_unless_asked(fed):
    every = fed.get("/api/events", headers=AUTH).json()
    assert every["events"] and every["next_offset"] is None
    assert "handoff" not in {e["kind"] for e in every["events"]}
    preds = fed.get("/api/events?kind=handoff", headers=AUTH).json()["events"]
    assert preds and {e["kind"] for e in preds} == {"handoff"}
    assert len({e["track_ids"][0] for e in preds}) == len(preds)


def test_events_page_with_offset_and_filter_by_sensor(fed):
    q = "kind=track_confirmed&kind=track_ended&kind=handoff"
    every = fed.get(f"/api/events?{q}", headers=AUTH).json()["events"]
    assert len(every) >= 2
    pages, offset, n = [], 0, 0
    while offset is not None:
        r = fed.get(f"/api/events?{q}&limit=1&offset={offset}", headers=AUTH).json()
        assert len(r["events"]) == 1
        pages += r["events"]
        offset, n = r["next_offset"], n + 1
    assert pages == every and n == len(every)
    sensors = sorted({s for e in every for s in e["sensors"]})
    for one in sensors:
        seen = fed.get(f"/api/events?{q}&sensor={one}", headers=AUTH).json()["events"]
        assert seen == [e for e in every if one in e["sensors"]]
    assert fed.get("/api/events?sensor=nope", headers=AUTH).status_code == 404
