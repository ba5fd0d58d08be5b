from __future__ import annotations

from server_helpers import AUTH, database_rows, walk


def post(c, records, key=None):
    body = {"detections": records} if key is None else {"detections": records, "batch_key": key}
    return c.post("/api/detections", headers=AUTH, json=body)


def test_ack_counts_reasons_and_is_durable(client, tmp_path, store_kw, store_backend):
    good = walk(n=5)
    bad = [
        {"t": 1.0, "sensor": "cam1", "bbox": [0, 0, 1], "class": "human"},  # malformed
        {"t": float("nan"), "sensor": "cam1", "bbox": [0, 0, 1, 1], "class": "human"},
        {"t": 1.0, "sensor": "cam1", "bbox": [0, 0, 1, 1], "class": "dog"},
        {"t": 1.0, "sensor": "camX", "bbox": [0, 0, 1, 1], "class": "human"},
        {"t": 1.0, "sensor": "cam1", "bbox": [0, 0, 5000, 1], "class": "human"},
        "not a record",
    ]
    r = client.post(
        "/api/detections",
        headers={**AUTH, "Content-Type": "application/json"},
        content=__import__("json").dumps({"detections": good + bad}),
    )
    assert r.status_code == 200, r.text
    ack = r.json()
    assert ack["accepted"] == 5 and ack["skipped"] == 6 and ack["n_records"] == 11
    assert ack["counts"] == {
        "malformed": 2,
        "nan": 1,
        "unknown_class": 1,
        "unknown_sensor": 1,
        "outside_image": 1,
        "time_backwards": 0,
    }
    assert sorted(i["index"] for i in ack["issues"]) == list(range(5, 11))
    # committed: another connection sees the rows the moment the ack is back
    rows = database_rows(tmp_path, store_kw, "SELECT id, t_s, sensor FROM detections ORDER BY id")
    assert [r[0] for r in rows] == ack["detection_ids"]
    assert [r[1] for r in rows] == [g["t"] for g in good]
    if store_backend == "sqlite":
        assert database_rows(tmp_path, store_kw, "PRAGMA journal_mode") == [("wal",)]
    listed = client.get("/api/detections", headers=AUTH).json()
    assert [d["t"] for d in listed] == [g["t"] for g in good]
    assert listed[0]["class"] == "vehicle" and listed[0]["local_id"] == "cam1-0"
    assert client.get("/api/detections?after_id=3", headers=AUTH).json()[0]["id"] == 4


def test_time_order_is_checked_across_batches(client):
    assert post(client, walk(n=5, t0=10.0)).json()["accepted"] == 5
    ack = post(client, walk(n=3, t0=5.0) + walk(sensor="cam2", n=2, t0=1.0)).json()
    assert ack["counts"]["time_backwards"] == 3 and ack["accepted"] == 2
    assert {i["index"] for i in ack["issues"]} == {0, 1, 2}


def test_batch_key_makes_a_resend_harmless(client):
    first = post(client, walk(n=4), key="cam1-000001").json()
    again = post(client, walk(n=4), key="cam1-000001").json()
    assert again["duplicate"] and not first["duplicate"]
    assert again["detection_ids"] == first["detection_ids"]
    assert len(client.get("/api/detections", headers=AUTH).json()) == 4


def test_bad_batches_are_4xx(client):
    assert client.post("/api/detections", headers=AUTH, json={"records": []}).status_code == 422
    assert client.post("/api/detections", headers=AUTH, json=[1, 2]).status_code == 422
    r = client.post("/api/detections", headers=AUTH, json={"detections": [], "batch_key": ""})
    assert r.status_code == 422
    r = post(client, [])
    assert r.status_code == 200 and r.json()["accepted"] == 0


def test_walking_object_becomes_a_track_with_filters(client):
    post(client, walk(n=30, t0=0.0))
    post(client, walk(sensor="cam2", n=30, t0=100.0, u0=300, v=600, cls="human"))
    tracks = client.get("/api/tracks", headers=AUTH).json()["tracks"]
    assert {t["cls"] for t in tracks} == {"vehicle", "human"}
    veh = next(t for t in tracks if t["cls"] == "vehicle")
    assert veh["sensors"] == ["cam1"] and veh["n_points"] == len(veh["points"]) > 10
    ts = [p["t_s"] for p in veh["points"]]
    assert ts == sorted(ts)
    # every point is made from stored detections
    ids = {d["id"] for d in client.get("/api/detections?limit=10000", headers=AUTH).json()}
    assert all(set(p["detection_ids"]) <= ids for p in veh["points"])

    def get(q):
        r = client.get(f"/api/tracks?{q}", headers=AUTH)
        assert r.status_code == 200, r.text
        return r.json()["tracks"]

    assert [t["cls"] for t in get("class=human")] == ["human"]
    assert [t["cls"] for t in get("sensor=cam1")] == ["vehicle"]
    window = get("t_from=2&t_to=3")
    assert [t["cls"] for t in window] == ["vehicle"]
    assert all(2 <= p["t_s"] <= 3 for p in window[0]["points"])
    assert get("t_from=50&t_to=60") == []
    p = veh["points"][0]
    box = f"{p['e_m'] - 1},{p['n_m'] - 1},{p['e_m'] + 1},{p['n_m'] + 1}"
    assert [t["id"] for t in get(f"bbox={box}")] == [veh["id"]]
    assert get("bbox=1000,1000,1001,1001") == []
    assert client.get(f"/api/tracks/{veh['id']}", headers=AUTH).json()["tracks"][0] == veh
    for q in (
        "bbox=1,2,3",
        "bbox=a,b,c,d",
        "bbox=3,0,1,1",
        "t_from=5&t_to=1",
        "class=dog",
        "t_from=nan",
    ):
        r = client.get(f"/api/tracks?{q}", headers=AUTH)
        assert r.status_code == 422, q
    assert client.get("/api/tracks/999", headers=AUTH).status_code == 404
    assert client.get(f"/api/tracks/{2**70}", headers=AUTH).status_code == 404
    assert client.get(f"/api/tracks/{-(2**70)}", headers=AUTH).status_code == 404


def test_one_track_by_id_is_the_listed_body(client):
    """``Store.track`` (one row by key) gives exactly the body ``Store.tracks`` lists."""
    from demtrack.server.store.codec import dumps_json, loads_json

    post(client, walk(n=30, t0=0.0))
    post(client, walk(sensor="cam2", n=30, t0=100.0, u0=300, v=600, cls="human"))
    store = client.app.state.console.store
    listed = store.tracks()
    assert listed, "the walk made no track"
    for body in listed:
        assert store.track(body["id"]) == body
    assert store.track(10**6) is None
    sample = {"a": [1, 2.5, None, "x"], "b": {"c": -3e-9}}
    assert loads_json(dumps_json(sample)) == sample
