"""Live events leave out tracks that ended long ago, and find exactly the same events."""

from __future__ import annotations

import numpy as np
import pytest
from test_activity_reference import random_scene

from demtrack.core.site import load_site
from demtrack.core.tracking.types import Track, TrackPoint
from demtrack.server.live_events import LiveEventParams, LiveEvents


class EveryTrack(LiveEvents):
    """The reference: every track of the window goes to the detectors."""

    @staticmethod
    def _in_play(track, live_ids, recent_s):
        return True


class Counting(LiveEvents):
    """The optimised one, counting the tracks it leaves out."""

    left_out = 0

    def _in_play(self, track, live_ids, recent_s):
        keep = LiveEvents._in_play(track, live_ids, recent_s)
        type(self).left_out += not keep
        return keep


@pytest.mark.parametrize("seed", range(2))
def test_leaving_out_long_ended_tracks_changes_no_event(sample_site_dir, seed):
    site = load_site(sample_site_dir)
    paths = random_scene(seed)
    points = {
        p.id: [
            TrackPoint(t, xyz, ("cam1",), (k,), None)
            for k, (t, xyz) in enumerate(zip(p.t_s, p.p_enu, strict=True))
        ]
        for p in paths
    }
    params = LiveEventParams(window_s=120.0, handoff_horizon_s=0.0)
    Counting.left_out = 0
    fast, ref = Counting(site, params), EveryTrack(site, params)
    t_end = max(float(p.t_s[-1]) for p in paths) + 30.0
    n_events = 0
    kinds = set()
    for t_now in np.arange(0.0, t_end, params.every_s):
        tracks, live = [], set()
        for p in paths:
            n = int(np.searchsorted(p.t_s, t_now, side="right"))
            if n == 0:
                continue
            tracks.append(Track(p.id, p.cls, tuple(points[p.id][:n])))
            if p.t_s[-1] > t_now:  # the object is still there: a live track
                live.add(p.id)
        got = fast.evaluate(tracks, live, float(t_now))
        want = ref.evaluate(tracks, live, float(t_now))
        assert got == want, t_now
        n_events += len(got)
        kinds |= {e["kind"] for e in got}
    assert n_events > 0 and kinds & {"convoy", "rendezvous", "loitering"}
    assert Counting.left_out > 0  # the shortcut was taken
