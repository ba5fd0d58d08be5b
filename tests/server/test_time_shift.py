"""Real UNIX times lose nothing: a scenario at t0 = 0 and at t0 = 1.8e9 s (2027) agrees.

Issue 27 moved every ``t_s`` from session seconds to UNIX seconds UTC. Anything that
treats a time as small (float32, ``int(t)``, windows from 0, times as indices, binning)
would change the tracks or the events when the same detections are replayed 57 years
later. The oracle is the same run at t0 = 0: the same tracks (ids, classes, sensors,
points) with every time moved by exactly the shift and every position within a
micrometre, and the same events (kinds, targets, states, times moved by the shift).
The shift is a whole number of seconds so the detectors' evaluation grid (every 1 s on
UNIX time) falls on the same scenario instants.
"""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.io.times import format_utc
from demtrack.core.site.folder import load_site
from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.live_events import LiveEventParams
from demtrack.server.store.database import Store
from demtrack.server.synopsis import trajectory

pytestmark = pytest.mark.timeout(900)
SHIFT_S = 1.8e9  # 2027-01-15T08:00:00Z
UNTIL_S = 120.0
#: Track positions agree to this (m). The times at 1.8e9 carry float64's 2.4e-7 s
#: grain, so the tracker's dt differ by up to that: at 10 m/s, 2.4e-6 m per step.
POS_TOL_M = 1e-5
T_TOL_S = 1e-6


def _run(site, tmp, name, records, shift_s):
    store = Store(tmp / f"{name}-{shift_s:.0f}.sqlite3")
    p = Pipeline(site, store, "kalman", lambda _m: None, events=LiveEventParams(window_s=90.0))
    p.start()
    batch: list[dict] = []
    for r in records:
        rec = {**r, "t": round(r["t"] + shift_s, 6)}
        if batch and rec["t"] >= batch[0]["t"] + 0.5:
            p.ingest(batch)
            batch = []
        batch.append(rec)
    if batch:
        p.ingest(batch)
    tracks, events = store.tracks(), store.activity()
    store.close()
    return tracks, events


@pytest.fixture(scope="module", params=["rendezvous", "loitering", "convoy", "vehicle-run"])
def runs(request, sample_site_dir, tmp_path_factory):
    site = load_site(sample_site_dir)
    sc = SAMPLE_SCENARIOS.make(site, request.param, seed=0)
    records = [
        {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": 0.5}
        for d in sc.detections
        if d.t_s < UNTIL_S
    ]
    tmp = tmp_path_factory.mktemp("shift")
    return _run(site, tmp, request.param, records, 0.0), _run(
        site, tmp, request.param, records, SHIFT_S
    )


def test_tracks_are_the_same_at_unix_times(runs):
    (tracks0, _), (tracks1, _) = runs
    assert len(tracks0) >= 1
    assert [(b["id"], b["cls"], b["sensors"], b["n_points"]) for b in tracks0] == [
        (b["id"], b["cls"], b["sensors"], b["n_points"]) for b in tracks1
    ]
    worst_m = worst_s = 0.0
    for a, b in zip(tracks0, tracks1, strict=True):
        np.testing.assert_allclose(
            np.array(b["gaps"]).reshape(-1, 2) - SHIFT_S,
            np.array(a["gaps"]).reshape(-1, 2),
            atol=T_TOL_S,
        )
        ta = np.array([p["t_s"] for p in a["points"]])
        tb = np.array([p["t_s"] for p in b["points"]])
        pa = np.array([[p["e_m"], p["n_m"], p["u_m"]] for p in a["points"]])
        pb = np.array([[p["e_m"], p["n_m"], p["u_m"]] for p in b["points"]])
        worst_s = max(worst_s, float(np.max(np.abs(tb - SHIFT_S - ta))))
        worst_m = max(worst_m, float(np.max(np.abs(pb - pa))))
        assert [p["detection_ids"] for p in a["points"]] == [
            p["detection_ids"] for p in b["points"]
        ]
        for step_s in (0.5, 1.0, 5.0):  # the synopsis thins by time steps: the same points
            sa, sb = trajectory(a, step_s), trajectory(b, step_s)
            assert [len(p.get("path") or ()) for p in sa["parts"]] == [
                len(p.get("path") or ()) for p in sb["parts"]
            ]
            assert sb["duration_s"] == pytest.approx(sa["duration_s"], abs=T_TOL_S)
    print(f"largest time difference {worst_s:.2e} s, position {worst_m:.2e} m")
    assert worst_s <= T_TOL_S and worst_m <= POS_TOL_M
    assert format_utc(tracks1[0]["points"][0]["t_s"]).startswith("2027-01-15T08:00:")


def test_events_are_the_same_at_unix_times(runs):
    (_, events0), (_, events1) = runs
    assert events0, "the scenario should make events (confirmed tracks at least)"
    print(sorted({e["kind"] for e in events0}), len(events0))

    def shape(ev):
        return (ev["kind"], ev["identity"], ev["state"], tuple(ev["track_ids"]), ev["open"])

    assert [shape(e) for e in events0] == [shape(e) for e in events1]
    for a, b in zip(events0, events1, strict=True):
        assert b["t_start_s"] - SHIFT_S == pytest.approx(a["t_start_s"], abs=T_TOL_S)
        assert b["t_end_s"] - SHIFT_S == pytest.approx(a["t_end_s"], abs=T_TOL_S)
        np.testing.assert_allclose(b["p_enu"], a["p_enu"], atol=POS_TOL_M)
