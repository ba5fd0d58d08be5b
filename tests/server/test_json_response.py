"""Polled reads sent by msgspec (:mod:`demtrack.server.json_response`) = what FastAPI sent.

``/api/tracks``, ``/api/synopsis`` and ``/api/detections`` return their bodies encoded as
they are, without FastAPI validating them against the route's ``response_model``.
Oracle: FastAPI's own path on the same data, ``TypeAdapter(model).dump_json`` of
``validate_python`` of what the handlers returned before (by alias, as FastAPI does),
compared value by value with JSON types kept apart (a bool is no number; an integer
equals the float of the same value, as in JSON), over a real ingest of two scenarios.
"""

from __future__ import annotations

import json
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import TypeAdapter
from server_helpers import AUTH, make_app, post_in_time_batches, scenario_records, walk

from demtrack.core.io.times import format_utc
from demtrack.core.site.folder import load_site
from demtrack.server.json_response import json_response
from demtrack.server.models import StoredDetectionOut, TracksOut
from demtrack.server.store.codec import encode_json
from demtrack.server.synopsis import synopsis
from demtrack.server.synopsis_models import SynopsisOut
from demtrack.server.time_fields import track_with_times
from demtrack.server.track_query import filter_tracks

pytestmark = pytest.mark.timeout(600)

T_MAX = 30.0


@pytest.fixture(scope="module")
def fed(sample_site_dir, tmp_path_factory, module_store_kw):
    """A server that ingested 30 s of two scenarios and a later walk, 0.5 s per batch."""
    site = load_site(sample_site_dir)
    recs = walk(n=20, t0=T_MAX + 60.0)  # a minute later: the scenarios' tracks have ended
    for name in ("vehicle-run", "pedestrians"):
        recs += scenario_records(site, name, T_MAX)
    recs.sort(key=lambda r: (r["t"], r["sensor"]))
    app = make_app(sample_site_dir, tmp_path_factory.mktemp("jr"), **module_store_kw)
    with TestClient(app) as c:
        post_in_time_batches(c, recs)
        yield c


def fastapi_json(model: Any, content: Any) -> Any:
    """What FastAPI sends for ``content`` returned by a route with ``response_model=model``."""
    adapter = TypeAdapter(model)
    return json.loads(adapter.dump_json(adapter.validate_python(content), by_alias=True))


def assert_same_json(got: Any, want: Any, where: str = "$") -> None:
    """Equal JSON values: same keys (any order), lengths, types; numbers by value."""
    if isinstance(want, dict):
        assert isinstance(got, dict), where
        assert sorted(got) == sorted(want), where
        for k, v in want.items():
            assert_same_json(got[k], v, f"{where}.{k}")
    elif isinstance(want, list):
        assert isinstance(got, list) and len(got) == len(want), where
        for k, (a, b) in enumerate(zip(got, want, strict=True)):
            assert_same_json(a, b, f"{where}[{k}]")
    elif isinstance(want, bool) or want is None or isinstance(want, str):
        assert type(got) is type(want) and got == want, (where, got, want)
    else:
        assert isinstance(want, int | float), where
        assert isinstance(got, int | float) and not isinstance(got, bool), (where, got)
        assert got == want, (where, got, want)


def _get(c: TestClient, path: str, params: dict[str, Any]) -> Any:
    r = c.get(path, headers=AUTH, params=params)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/json"
    return r.json()


TRACK_QUERIES: list[dict[str, Any]] = [
    {},
    {"t_from": 5.0, "t_to": 25.0},
    {"t_from": T_MAX - 2.0},
    {"t_to": 10.0, "class": "vehicle"},
    {"class": "human"},
    {"sensor": "cam2"},
    {"bbox": "-200,-200,200,200", "t_from": 3.0},
]


@pytest.mark.parametrize("params", TRACK_QUERIES)
def test_tracks_are_what_fastapi_sent(fed, params):
    state = fed.app.state.console
    got = _get(fed, "/api/tracks", params)
    old = {
        "tracks": [
            track_with_times(t)  # the answer's ISO time beside every point's t_s
            for t in filter_tracks(
                state,
                params.get("t_from"),
                params.get("t_to"),
                params.get("class"),
                params.get("sensor"),
                params.get("bbox"),
            )
        ]
    }
    assert_same_json(got, fastapi_json(TracksOut, old))


def test_the_tracks_compared_have_substance(fed):
    tracks = _get(fed, "/api/tracks", {})["tracks"]
    assert len(tracks) >= 3 and sum(len(t["points"]) for t in tracks) > 200
    assert any(t["gaps"] for t in tracks) and any(not t["live"] for t in tracks)
    assert any(t["live"] for t in tracks)
    assert not _get(fed, "/api/tracks", {"t_from": 1e6})["tracks"]


SYNOPSIS_QUERIES: list[dict[str, Any]] = [
    {},
    {"t0": 5.0, "t1": 25.0, "step_s": 0.5},
    {"t1": T_MAX, "step_s": 0.02},
    {"t0": 10.0, "t1": 12.0},
    {"t0": 0.0, "t1": 100.0, "class": "vehicle", "step_s": 2.0},
    {"sensor": "cam1", "step_s": 0.7},
]


def _old_synopsis(state, params: dict[str, Any]) -> dict[str, Any]:
    t0, t1 = params.get("t0"), params.get("t1")
    cls, sensor = params.get("class"), params.get("sensor")
    bodies = filter_tracks(state, t0, t1, cls, sensor, None)
    events = state.store.activity(t_from=t0, t_to=t1)
    filtered = cls is not None or sensor is not None
    return synopsis(bodies, events, t0, t1, params.get("step_s", 1.0), filtered)


@pytest.mark.parametrize("params", SYNOPSIS_QUERIES)
def test_synopsis_is_what_fastapi_sent(fed, params):
    got = _get(fed, "/api/synopsis", params)
    assert_same_json(got, fastapi_json(SynopsisOut, _old_synopsis(fed.app.state.console, params)))


def test_the_synopsis_compared_has_substance(fed):
    syn = _get(fed, "/api/synopsis", {})
    parts = [p for t in syn["trajectories"] for p in t["parts"]]
    assert {p["kind"] for p in parts} == {"tracked", "gap"}
    assert syn["events"] and any(t["event_ids"] for t in syn["trajectories"])


def test_synopsis_events_without_a_row_id_get_the_models_default(fed, monkeypatch):
    state = fed.app.state.console
    params = {"t0": 0.0, "t1": T_MAX}
    want = fastapi_json(SynopsisOut, _old_synopsis(state, params))
    stored = state.store.activity
    monkeypatch.setattr(
        state.store,
        "activity",
        lambda **kw: [{k: v for k, v in e.items() if k != "id"} for e in stored(**kw)],
    )
    got = _get(fed, "/api/synopsis", params)
    assert got["events"] and all(e["id"] is None for e in got["events"])
    assert not any(t["event_ids"] for t in got["trajectories"])
    # Otherwise the same answer, and still what FastAPI would have sent for it.
    assert_same_json(got, fastapi_json(SynopsisOut, _old_synopsis(state, params)))
    for e in want["events"]:
        e["id"] = None
    for t in want["trajectories"]:
        t["event_ids"] = []
    assert_same_json(got, want)


DETECTION_QUERIES: list[dict[str, Any]] = [
    {},
    {"after_id": 100, "limit": 50},
    {"limit": 10_000},
    {"t_from": 5.0, "t_to": 6.0},
    {"t_from": 20.0, "sensor": ["cam1"], "limit": 30},
]


def _old_detections(state, params: dict[str, Any]) -> list[dict[str, Any]]:
    """The rows the handler returned before (``cls`` by field name)."""
    after_id, limit = params.get("after_id", 0), params.get("limit", 1000)
    if "t_from" in params or "t_to" in params or "sensor" in params:
        lo, hi = params.get("t_from", float("-inf")), params.get("t_to", float("inf"))
        sensors = sorted(set(params.get("sensor") or state.site.sensors))
        rows = state.store.detections_in_window(sensors, lo, hi, after_id, limit)
    else:
        rows = state.store.detections(after_id, limit)
    return [
        {
            "id": i,
            "t": d.t_s,
            "time_utc": format_utc(d.t_s),
            "sensor": d.sensor,
            "bbox": d.bbox,
            "cls": d.cls,
            "score": d.score,
            "local_id": d.local_id,
        }
        for i, d in rows
    ]


@pytest.mark.parametrize("params", DETECTION_QUERIES)
def test_detections_are_what_fastapi_sent(fed, params):
    got = _get(fed, "/api/detections", params)
    want = fastapi_json(list[StoredDetectionOut], _old_detections(fed.app.state.console, params))
    assert got and "class" in got[0] and "cls" not in got[0]
    assert_same_json(got, want)
    assert [list(d) for d in got] == [list(d) for d in want]  # the model's key order


def test_the_routes_still_document_their_models(fed):
    paths = fed.app.openapi()["paths"]

    def schema(path: str) -> Any:
        return paths[path]["get"]["responses"]["200"]["content"]["application/json"]["schema"]

    assert schema("/api/tracks") == {"$ref": "#/components/schemas/TracksOut"}
    assert schema("/api/synopsis") == {"$ref": "#/components/schemas/SynopsisOut"}
    det = schema("/api/detections")
    assert det["type"] == "array" and det["items"]["$ref"].endswith("/StoredDetectionOut")


def test_json_response_is_compact_json():
    value = {"a": [1, 2.5, None, True], "b": (1.0, -0.0), "é": "x\n", "n": {"k": 1e-7}}
    r = json_response(value, status_code=201)
    assert r.status_code == 201 and r.media_type == "application/json"
    assert r.headers["content-type"] == "application/json"
    assert r.body == encode_json(value)
    assert json.loads(r.body) == json.loads(json.dumps(value))
    assert b" " not in r.body.replace(b"\\n", b"")
