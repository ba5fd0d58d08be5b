"""Reading only a live track's changed points gives the body a whole read gives.

Oracle: after every write of a random sequence (points appended, tails revised, bodies
rewritten from the start or cut shorter, whole bodies, the table replaced, writes by a
second store on the same file), every body the :class:`TrackCache` returns equals the
store's whole decode of it (``Store.track``) and the writer's own list of points; and
bodies built from a held version and the changed points (``tails``) are really used.
"""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.server.store.codec import dumps_json
from demtrack.server.store.database import Store
from demtrack.server.store.queries import TrackTail
from demtrack.server.track_cache import TrackCache
from demtrack.server.track_history import PointCuts


def test_a_chain_of_writes_gives_its_smallest_start():
    cuts = PointCuts()
    cuts.record({1: 5}, {1: 7}, {1: 10})
    cuts.record({1: 7}, {1: 9}, {1: 12})
    cuts.record({2: 8}, {2: 11}, {2: 0})
    assert cuts.first_changed(1, 5, 9) == 10
    assert cuts.first_changed(1, 7, 9) == 12
    assert cuts.first_changed(1, 5, 7) == 10
    assert cuts.first_changed(2, 8, 11) == 0


def test_unknown_chains_are_none():
    cuts = PointCuts(writes_per_track=2)
    cuts.record({1: 3}, {1: 4}, {1: 5})
    cuts.record({1: 4}, {1: 6}, {1: 6})
    cuts.record({1: 6}, {1: 7}, {1: 2})
    assert cuts.first_changed(1, 3, 7) is None  # the write from 3 is no longer kept
    assert cuts.first_changed(1, 4, 7) == 2
    assert cuts.first_changed(1, 2, 7) is None  # a version this store never wrote
    assert cuts.first_changed(1, 7, 7) is None  # nothing changed: nothing to read
    assert cuts.first_changed(1, 4, 5) is None  # no write reached 5
    assert cuts.first_changed(9, 1, 2) is None
    cuts.record({}, {2: 3}, {2: 0})  # a new track: no version before it
    assert cuts.first_changed(2, -1, 3) == 0
    cuts.clear()
    assert cuts.first_changed(1, 4, 7) is None


def test_a_rolled_back_write_only_lowers_the_start():
    cuts = PointCuts()
    cuts.record({1: 7}, {1: 8}, {1: 3})  # rolled back: version 8 never committed ...
    cuts.record({1: 7}, {1: 8}, {1: 12})  # ... and reused by the next write
    assert cuts.first_changed(1, 7, 8) == 3
    cuts.record({1: 8}, {1: 10}, {1: 14})
    cuts.record({1: 8}, {1: 11}, {1: 1})  # rolled back with a number past the reader's
    assert cuts.first_changed(1, 7, 10) == 3


def test_tracks_forgotten_least_recently_written_first():
    cuts = PointCuts(max_tracks=2)
    for i in (1, 2, 3):
        cuts.record({i: 1}, {i: 2}, {i: 4})
    assert cuts.first_changed(1, 1, 2) is None
    assert cuts.first_changed(3, 1, 2) == 4


def _row(track_id: int, points: list[dict], start: int) -> dict:
    t = [p["t_s"] for p in points]
    head = {"id": track_id, "cls": "vehicle", "live": True, "n_points": len(points)}
    return dict(
        id=track_id, cls="vehicle", t_start=min(t), t_end=max(t), e_min=0.0, n_min=0.0,
        e_max=1.0, n_max=1.0, sensors=["a"], live=True, body=dumps_json(head),
        points_from=start, point_texts=[dumps_json(p) for p in points[start:]],
    )  # fmt: skip


def _point(rng: np.random.Generator, t: float) -> dict:
    return {"t_s": t, "e_m": float(rng.normal()), "n_m": float(rng.normal()), "z": [1, 2]}


@pytest.mark.parametrize("seed", range(6))
def test_cached_bodies_equal_whole_reads_through_random_writes(tmp_path, seed):
    rng = np.random.default_rng(seed)
    path = tmp_path / "s.sqlite3"
    store = Store(path)
    other = Store(path)  # another connection writing the same file now and then
    cache = TrackCache(store)
    truth: dict[int, list[dict]] = {}
    clock = {i: 0.0 for i in range(1, 5)}
    for step in range(160):
        rows = []
        for i in rng.choice(4, size=int(rng.integers(1, 4)), replace=False) + 1:
            i = int(i)
            pts = truth.get(i, [])
            kind = rng.random()
            if kind < 0.55 or not pts:  # append, revising the last few
                start = max(0, len(pts) - int(rng.integers(0, 4)))
                new = [_point(rng, clock[i] + k * 0.1) for k in range(int(rng.integers(1, 6)))]
                clock[i] += 0.1 * len(new)
                pts = pts[:start] + [_point(rng, p["t_s"]) for p in pts[start:]] + new
            elif kind < 0.7:  # rewritten from the start
                start = 0
                pts = [_point(rng, p["t_s"]) for p in pts]
            elif kind < 0.8:  # cut shorter
                start = int(rng.integers(0, len(pts)))
                pts = pts[: start + int(rng.integers(0, 2))]
                if not pts:
                    pts, start = [_point(rng, clock[i])], 0
            elif kind < 0.9:  # nothing rewritten (an end, a new head)
                start = len(pts)
            else:  # out of time order
                start = max(0, len(pts) - 1)
                pts = pts[:start] + [_point(rng, clock[i] - 5.0)]
            truth[i] = pts
            rows.append(_row(i, pts, start))
        writer = other if rng.random() < 0.1 else store
        if rng.random() < 0.03:
            writer.write_derived(
                [], [_row(i, p, 0) for i, p in truth.items()], [], replace_tracks=True
            )
        else:
            writer.write_derived([], rows, [])
        if step % 3 == 0 or rng.random() < 0.3:
            got = {t.id: t for t in cache.select()}
            assert set(got) == set(truth)
            for i, track in got.items():
                assert track.body == store.track(i)
                assert track.body["points"] == truth[i]
                assert track.t_s == [p["t_s"] for p in truth[i]]
                t = track.t_s
                assert track.in_order == all(a <= b for a, b in zip(t, t[1:], strict=False))
    assert cache.tails > 20


def test_track_rows_gives_tails_only_when_asked(tmp_path):
    store = Store(tmp_path / "s.sqlite3")
    pts = [{"t_s": float(k)} for k in range(5)]
    store.write_derived([], [_row(1, pts, 0)], [])
    ((_, rev, text),) = store.track_rows({})
    store.write_derived([], [_row(1, [*pts[:3], {"t_s": 3.5}], 3)], [])
    ((_, rev2, whole),) = store.track_rows({1: rev})
    assert isinstance(whole, str)
    ((_, _, tail),) = store.track_rows({1: rev}, tails=True)
    assert tail == TrackTail(tail.head, 3, ['{"t_s":3.5}'])
    assert rev2 > rev
