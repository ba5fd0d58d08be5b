"""One client's bad batch never fails another's (issue 26, items 12 and 14).

A JSON integer longer than 308 digits in ``t``, ``bbox`` or ``score`` overflowed
``float()`` (an uncaught ``OverflowError``): a 500, and every batch of the same group
commit failed with it. Now it is a ``malformed`` record, counted and skipped; and should a
batch still fail inside a group commit, the others are committed on their own.
"""

from __future__ import annotations

import threading

import pytest
from server_helpers import AUTH, vehicle_run_pipeline, walk

from demtrack.core.io.detections import read_detection_records
from demtrack.server.ingest.group_commit import Request

pytestmark = pytest.mark.timeout(300)
BIG = 10**400  # 401 digits: beyond a float


@pytest.mark.parametrize("field", ["t", "bbox", "score"])
def test_a_huge_integer_is_a_malformed_record_with_one_short_line(field):
    rec = {"t": 1.0, "sensor": "cam1", "bbox": [0, 0, 10, 10], "class": "human", "score": 0.5}
    if field == "bbox":
        rec["bbox"] = [0, 0, BIG, 10]
    else:
        rec[field] = BIG
    dets, report = read_detection_records([rec])
    assert dets == [] and report.counts["malformed"] == 1
    (issue,) = report.examples
    want = f"{field} must be a number a float can hold, got an integer of 401 digits"
    assert issue.message == want


def test_ingest_with_a_400_digit_t_is_no_server_error(client):
    text = '{"detections": [{"t": %s, "sensor": "cam1", "bbox": [0, 0, 1, 1], "class": "human"}]}'
    r = client.post(
        "/api/detections",
        headers={**AUTH, "Content-Type": "application/json"},
        content=text % ("9" * 400),
    )
    assert r.status_code == 200, r.text
    ack = r.json()
    assert ack["accepted"] == 0 and ack["counts"]["malformed"] == 1
    assert ack["issues"][0]["message"].endswith("an integer of 400 digits")


def test_a_failing_batch_in_a_group_leaves_the_others_acknowledged(sample_site_dir, tmp_path):
    _, p, _ = vehicle_run_pipeline(sample_site_dir, tmp_path, 0.0)
    real = p._validate

    def validate(records):
        if any(isinstance(r, dict) and r.get("poison") for r in records):
            raise RuntimeError("poisoned batch")
        return real(records)

    p._validate = validate
    good1 = Request(walk(n=5), "good-1")
    bad = Request([{**walk(sensor="cam2", n=1)[0], "poison": True}], "bad")
    good2 = Request(walk(sensor="cam2", n=5, t0=0.1), "good-2")
    with p._lock:
        p._ingest_group([good1, bad, good2])
    assert good1.error is None and good2.error is None
    assert good1.ack["accepted"] == 5 and good2.ack["accepted"] == 5
    assert isinstance(bad.error, RuntimeError) and bad.ack is None
    stored = [d.sensor for _, d in p.store.detections(0, 100)]
    assert stored == ["cam1"] * 5 + ["cam2"] * 5
    # the counters follow what was stored (the failed batch's time never counted)
    assert p._n_det == {"cam1": 5, "cam2": 5}
    p.store.close()


def test_a_poisoned_client_beside_good_ones_fails_no_good_batch(sample_site_dir, tmp_path):
    _, p, _ = vehicle_run_pipeline(sample_site_dir, tmp_path, 0.0)
    n_batches = 40
    results: dict[str, list] = {"cam1": [], "cam2": [], "poison": []}

    def camera(sensor: str) -> None:
        for k in range(n_batches):
            recs = walk(sensor=sensor, n=3, t0=k * 0.6, dt=0.2)
            try:
                results[sensor].append(p.ingest(recs, f"{sensor}-{k}"))
            except Exception as exc:  # noqa: BLE001 - what the test counts
                results[sensor].append(exc)

    def poison() -> None:
        for k in range(n_batches):
            recs = [{"t": BIG, "sensor": "cam3", "bbox": [0, 0, BIG, 1], "class": "human"}]
            try:
                results["poison"].append(p.ingest(recs, f"poison-{k}"))
            except Exception as exc:  # noqa: BLE001
                results["poison"].append(exc)

    threads = [threading.Thread(target=camera, args=(s,)) for s in ("cam1", "cam2")]
    threads.append(threading.Thread(target=poison))
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for sensor in ("cam1", "cam2"):
        acks = results[sensor]
        assert all(isinstance(a, dict) for a in acks), [a for a in acks if not isinstance(a, dict)]
        assert sum(a["accepted"] for a in acks) == 3 * n_batches
    assert all(isinstance(a, dict) and a["counts"]["malformed"] == 1 for a in results["poison"])
    assert p.n_batches == 3 * n_batches
    p.store.close()
