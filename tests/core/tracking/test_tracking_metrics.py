"""Track metrics on hand-built tracks."""

import numpy as np
import pytest

from demtrack.core.tracking.metrics import (
    count_fix_jumps,
    evaluate,
    match_tracks,
    track_position_at,
)
from demtrack.core.tracking.types import Fix, Track, TrackPoint, TruthPath

T = np.arange(0.0, 10.01, 0.1)
A = TruthPath(1, "vehicle", T, np.column_stack([T, np.zeros_like(T), np.zeros_like(T)]))
B = TruthPath(2, "vehicle", T, np.column_stack([T, np.full_like(T, 20.0), np.zeros_like(T)]))


def _track(tid, t, xy, cls="vehicle", gaps=()):
    pts = [
        TrackPoint(ti, [x, y, 0.0], ("c",), (k,))
        for k, (ti, (x, y)) in enumerate(zip(t, xy, strict=True))
    ]
    return Track(tid, cls, pts, {"c"}, gaps)


def test_perfect_tracks_score_zero():
    tracks = [_track(1, T, A.p_enu[:, :2]), _track(2, T, B.p_enu[:, :2])]
    m = evaluate(tracks, [A, B])
    assert m.rmse_m == 0 and m.p95_m == 0 and m.n_jumps == 0
    assert m.id_switches == 0 and m.fragmentation == 0 and m.n_false_tracks == 0
    assert m.coverage == 1.0 and m.ospa_m == 0 and m.gospa_m == 0
    assert m.n_points == 2 * len(T)


def test_rmse_p95_and_jumps():
    xy = A.p_enu[:, :2] + [0.0, 0.5]
    xy[10] += [0.0, 4.0]  # one point 4.5 m off: a jump
    m = evaluate([_track(1, T, xy)], [A])
    err = np.full(len(T), 0.5)
    err[10] = 4.5
    assert m.rmse_m == pytest.approx(np.sqrt(np.mean(err**2)))
    assert m.p95_m == pytest.approx(np.percentile(err, 95))
    assert m.n_jumps == 1


def test_swapped_identities_count_two_switches():
    half = T < 5
    xy1 = np.where(half[:, None], A.p_enu[:, :2], B.p_enu[:, :2])
    xy2 = np.where(half[:, None], B.p_enu[:, :2], A.p_enu[:, :2])
    m = evaluate([_track(1, T, xy1), _track(2, T, xy2)], [A, B], dt_eval_s=0.1)
    assert m.id_switches == 2
    assert m.fragmentation == 2


def test_a_broken_track_is_one_fragment_and_one_switch():
    first, second = T <= 4.0, T >= 6.0
    tracks = [_track(1, T[first], A.p_enu[first, :2]), _track(2, T[second], A.p_enu[second, :2])]
    m = evaluate(tracks, [A])
    assert m.fragmentation == 1 and m.id_switches == 1
    assert m.coverage == pytest.approx(np.mean((T <= 4.0) | (T >= 6.0)), abs=0.03)
    assert match_tracks(tracks, [A]) == {1: 1, 2: 1}


def test_false_and_wrong_class_tracks_are_not_matched():
    far = _track(3, T, A.p_enu[:, :2] + [0, 50.0])
    walker = _track(4, T, A.p_enu[:, :2], cls="human")
    assert match_tracks([far, walker], [A]) == {3: None, 4: None}
    m = evaluate([_track(1, T, A.p_enu[:, :2]), far], [A])
    assert m.n_false_tracks == 1 and m.rmse_m == 0.0
    assert m.ospa_m > 0  # the extra track is penalised by OSPA


def test_position_at_interpolates_and_respects_gaps():
    tr = _track(1, [0.0, 1.0, 5.0, 6.0], [[0, 0], [1, 0], [5, 0], [6, 0]], gaps=[(1.0, 5.0)])
    np.testing.assert_allclose(track_position_at(tr, 0.5), [0.5, 0])
    assert track_position_at(tr, 3.0) is None
    assert track_position_at(tr, 7.0) is None
    np.testing.assert_allclose(track_position_at(tr, 1.0), [1.0, 0])


def test_count_fix_jumps():
    def fix(t, hits):
        return Fix(t, "c", "vehicle", 0, [0, 0, 10], [1, 0, -1], hits, [0.5] * len(hits))

    fixes = [
        fix(1.0, [[1.0, 0, 0]]),
        fix(2.0, [[-5.0, 0, 3], [2.0, 0, 0]]),
        fix(3.0, [[3.0, 19.0, 0]]),
    ]
    assert count_fix_jumps(fixes, [A], hit="first") == 2
    assert count_fix_jumps(fixes, [A], hit="last") == 1
    assert count_fix_jumps(fixes, [A, B], hit="last") == 0
