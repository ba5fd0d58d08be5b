"""A convoy that vehicles join is one episode whose members change, not one per membership.

Three copies of the sample site's ``convoy`` case, 4 s and 9 s apart, make one column of
nine cars on one road; the live detector first sees its head and then more cars as they
qualify (100 m behind a leader). The server used to announce a new convoy for each new
membership and end the previous one (six convoys for this column, the map covered in their
labels); now it is one episode, keyed once, whose ``track_ids`` grow, streamed as a start
and its updates. The oracle for its members is the offline detector on the final tracks;
for their order (the column's, head first), the order in which they pass one place.
"""

from __future__ import annotations

import numpy as np
import pytest
from server_helpers import stored_messages, time_batches

from demtrack.core.activity.convoy import detect_convoys
from demtrack.core.site.folder import load_site
from demtrack.samplesite.activity_scenarios import make_activity_scenario
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.live_events import LiveEventParams
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


def test_a_growing_column_is_one_convoy_episode(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    case = make_activity_scenario(site, "convoy").scenario
    records = [
        {"t": d.t_s + offset, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls}
        for offset in (0.0, 4.0, 9.0)
        for d in case.detections
    ]
    records.sort(key=lambda r: (r["t"], r["sensor"]))
    p = Pipeline(
        site, Store(tmp_path / "c.sqlite3"), "kalman", lambda _m: None, events=LiveEventParams()
    )
    p.start()
    for batch in time_batches(records, 1.0):
        p.ingest(batch)

    convoys = [a for a in p.store.activity() if a["kind"] == "convoy"]
    assert len(convoys) == 1, [(a["track_ids"], a["t_start_s"], a["t_end_s"]) for a in convoys]
    episode = convoys[0]
    # the members: every vehicle the offline detector puts in a convoy on the final tracks
    offline = detect_convoys([t for t in p.tracker.tracks() if t.cls == "vehicle"])
    in_convoys = {i for e in offline for i in e.track_ids}
    assert len(in_convoys) >= 6
    assert set(episode["track_ids"]) == in_convoys

    # in column order (head first): the order in which the members pass the place where
    # the head was when the convoy began
    tracks = {t.id: t for t in p.tracker.tracks()}
    head = tracks[episode["track_ids"][0]]
    place = head.p_enu[np.searchsorted(head.t_s, episode["t_start_s"]), :2]
    passed = []
    for i in episode["track_ids"]:
        miss = np.hypot(*(tracks[i].p_enu[:, :2] - place).T)
        assert miss.min() < 1.0  # every member drives through it
        passed.append(tracks[i].t_s[int(np.argmin(miss))])
    assert passed == sorted(passed) and len(set(passed)) == len(passed)

    messages = [
        m["event"]
        for m in stored_messages(p.store)
        if m["type"] == "event" and m["kind"] == "convoy"
    ]
    assert {m["key"] for m in messages} == {episode["key"]}
    assert messages[0]["state"] == "start" and len(messages) > 1
    assert {m["state"] for m in messages[1:]} <= {"update", "end"}
    sizes = [len(m["track_ids"]) for m in messages]
    assert sizes[0] < sizes[-1] == len(episode["track_ids"])  # cars joined as they qualified
    assert messages[-1]["track_ids"] == episode["track_ids"]
    # an update that only grows the span is stored, not streamed (the end carries it)
    assert messages[-1]["t_end_s"] <= episode["t_end_s"]
