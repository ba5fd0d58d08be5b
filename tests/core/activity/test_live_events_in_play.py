"""Live events leave out tracks that ended long ago, and find exactly the same events."""

from __future__ import annotations

import numpy as np
import pytest
from test_activity_reference import random_scene

from demtrack.core.site.folder import load_site
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
        kinds |= {e["kind"] for e, _ in got}
    assert n_events > 0 and kinds & {"convoy", "rendezvous", "loitering"}
    assert Counting.left_out > 0  # the shortcut was taken


@pytest.mark.parametrize("seed", range(3))
def test_thinned_window_keeps_the_points_of_the_grid_rule(seed):
    """``_thin`` keeps, per ``sample_s`` grid time, the first point at or after it, and the
    last point (the rule written out with ``np.unique``/``np.union1d``, as it first was).

    Since issue 27 the grid is on times relative to the window's first point, and a point
    within 1 us of a grid time (or of the window's start) counts as on it: the same track
    is thinned alike at t0 = 0 and at UNIX times (1.8e9 s), where float64's grain is
    2.4e-7 s and an exact tie would be broken by rounding.
    """
    from demtrack.server.live_events import _thin

    rng = np.random.default_rng(seed)
    n = 400
    t = 1000.0 + np.cumsum(rng.choice([0.0, 0.1, 0.1, 0.7], n))
    xyz = rng.normal(0, 10, (n, 3))
    track = Track(
        7, "human", [TrackPoint(t[k], xyz[k], (f"cam{k % 3}",), (k,), None) for k in range(n)]
    )
    shifted = Track(
        7, "human", [TrackPoint(t[k] + 1.8e9, xyz[k], ("cam0",), (k,), None) for k in range(n)]
    )
    tol = 1e-6
    for t_from, sample_s in [(0.0, 0.5), (t[n // 2], 0.3), (t[-1], 0.5), (t[5] + 1e-3, 1.0)]:
        k0 = int(np.searchsorted(t, t_from - tol))
        tt = t[k0:]
        rel = tt - tt[0]
        grid = np.arange(0.0, rel[-1] + sample_s, sample_s) - tol
        keep = np.union1d(
            np.unique(np.minimum(np.searchsorted(rel, grid), len(tt) - 1)), [len(tt) - 1]
        )
        w = _thin(track, t_from, sample_s)
        assert w is not None
        np.testing.assert_array_equal(w.t_s, tt[keep])
        np.testing.assert_array_equal(w.p_enu, xyz[k0 + keep])
        assert w.sensors == tuple((f"cam{(k0 + k) % 3}",) for k in keep)
        far = _thin(shifted, t_from + 1.8e9 if t_from else 0.0, sample_s)
        assert far is not None
        np.testing.assert_array_equal(far.index, w.index)  # the same points at UNIX times
    assert _thin(track, t[-1] + 1.0, 0.5) is None
