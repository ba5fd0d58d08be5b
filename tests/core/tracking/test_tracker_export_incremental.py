"""Track values exported while a track grows equal those built from scratch."""

from __future__ import annotations

import numpy as np
import pytest
import tracking_synthetic as syn

from demtrack.core.tracking import build_tracker
from demtrack.core.tracking.tracker import find_gaps
from demtrack.core.tracking.types import Track


def _from_scratch(track: Track, gap_threshold_s: float) -> Track:
    return Track(
        track.id,
        track.cls,
        track.points,
        frozenset().union(*(p.sensors for p in track.points)),
        tuple(find_gaps(np.array([p.t_s for p in track.points]), gap_threshold_s)),
    )


def _assert_same(got: Track, want: Track) -> None:
    assert got.points == want.points  # the same point objects
    assert got.sensors == want.sensors
    assert got.gaps == want.gaps
    np.testing.assert_array_equal(got.t_s, want.t_s)
    np.testing.assert_array_equal(got.p_enu, want.p_enu)
    assert not got.t_s.flags.writeable and not got.p_enu.flags.writeable


@pytest.mark.parametrize("make", [syn.scenario_loop, syn.scenario_two_sensors])
def test_tracks_read_after_every_fix_equal_tracks_built_from_scratch(make):
    """Reading after every fix exercises the grown path (smoothing revises the tail,
    confirmation trims, a gap opens when the fixes stop); every value is checked."""
    sc = make()
    tr = build_tracker("kalman")
    threshold = tr.config.gap_threshold_s
    n_checked = 0
    for f in sc.fixes:
        if 10.0 <= f.t_s < 12.0:  # an absence shorter than the end: a gap in one track
            continue
        tr.update(f)
        for track in tr.tracks():
            _assert_same(track, _from_scratch(track, threshold))
            n_checked += 1
    tr.flush()
    for track in tr.tracks():
        _assert_same(track, _from_scratch(track, threshold))
    assert n_checked > 100
    assert any(t.gaps for t in tr.tracks())
