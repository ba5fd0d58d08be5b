"""``Tracker.tracks(ended_after_s=...)``: the recent ended tracks, without the old ones."""

from __future__ import annotations

import tracking_synthetic as syn

from demtrack.core.tracking import TrackerConfig, build_tracker


def test_ended_after_keeps_live_tracks_and_recent_ended_ones():
    sc = syn.scenario_loop()
    tr = build_tracker("kalman", config=TrackerConfig(reacquire_s=0.0))
    for f in sc.fixes:
        if not 10.0 <= f.t_s < 16.0:  # a long absence: the first track ends
            tr.update(f)
    tr.flush()
    everything = tr.tracks()
    live_ids = {t.id for t in tr.tracks(include_ended=False)}
    ended = [t for t in everything if t.id not in live_ids]
    assert len(ended) == 1 and len(live_ids) == 1
    t_end = ended[0].points[-1].t_s
    assert t_end < 10.0
    for after in (-1e9, t_end - 1.0, t_end, t_end + 1e-9, 30.0, 1e9):
        got = tr.tracks(ended_after_s=after)
        want = [t for t in everything if t.id in live_ids or t.points[-1].t_s >= after]
        assert [t.id for t in got] == [t.id for t in want], after
        assert [t.points for t in got] == [t.points for t in want]
    live_only = tr.tracks(ended_after_s=-1e9, include_ended=False)
    assert [t.id for t in live_only] == sorted(live_ids)
