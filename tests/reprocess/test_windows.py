"""Cutting the work up changes nothing: windows, geolocation chunks, one-call references."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from demtrack.core.geolocation.fix_builder import build_fixes
from demtrack.core.tracking import TrackerConfig, run_tracker
from demtrack.reprocess.archive import detections_of
from demtrack.reprocess.engines import run_local
from demtrack.reprocess.fix_columns import FixColumns
from demtrack.reprocess.plan import make_plan
from demtrack.reprocess.run import ReprocessSettings, plan_run
from demtrack.reprocess.tasks import segment_tracks, site_at, track_window

METHOD = "multi-hypothesis-road"  # particle filters: random draws, the hardest case


@pytest.fixture(scope="module")
def planned(site12_dir, small_archive):
    read, plan = plan_run(str(site12_dir), str(small_archive), ReprocessSettings(METHOD))
    return read, plan


@pytest.fixture(scope="module")
def geolocated(site12_dir, planned):
    read, plan = planned
    return run_local(plan, read.table, str(site12_dir), METHOD).geo


def _key(tracks, det_of=None):
    """Comparable tracks: id, class, and per point time, position and detection ids."""
    out = []
    for t in tracks:
        pts = []
        for p in t.points:
            ids = p.fix_indices if det_of is None else tuple(det_of[i] for i in p.fix_indices)
            pts.append((p.t_s, tuple(np.asarray(p.p_enu).tolist()), ids))
        out.append((t.id, t.cls, tuple(pts)))
    return out


def _busiest(plan):
    return max(plan.segments, key=lambda s: sum(len(plan.parts[k].rows) for k in s.parts))


def test_one_window_is_run_tracker(site12_dir, planned, geolocated):
    # Reference: the library's batch tracker on the segment's fixes, in one call.
    _, plan = planned
    seg = _busiest(plan)
    site = site_at(str(site12_dir))
    cols = FixColumns.concat([geolocated[k].fixes for k in seg.parts]).sorted()
    # the segment's parts may hold the neighbouring segments' fixes too: its bounds cut
    cols = cols.take(np.flatnonzero((cols.t_s >= seg.t_first) & (cols.t_s <= seg.t_last)))
    fixes = cols.to_fixes()
    ref = run_tracker(fixes, METHOD, roads=site.roads, config=TrackerConfig(seed=seg.seed))
    assert ref
    det_of = [f.detection_index for f in fixes]
    parts = [geolocated[k] for k in seg.parts]
    bounds = (seg.t_first, seg.t_last)
    one = track_window(
        str(site12_dir), METHOD, seg.seed, None, parts, (-np.inf, np.inf), True, bounds
    )
    assert _key(one.tracks) == _key(ref, det_of)


@settings(
    max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(window_s=st.floats(min_value=0.05, max_value=120.0))
def test_windows_hand_the_exact_state_on(site12_dir, planned, geolocated, window_s):
    _, plan = planned
    seg = _busiest(plan)
    parts = [geolocated[k] for k in seg.parts]
    bounds = (seg.t_first, seg.t_last)
    whole = track_window(
        str(site12_dir), METHOD, seg.seed, None, parts, (-np.inf, np.inf), True, bounds
    )
    edges = [
        seg.t_first + k * window_s for k in range(int((seg.t_last - seg.t_first) / window_s) + 1)
    ]
    windows = list(zip(edges, [*edges[1:], np.inf], strict=True))
    results, prev = [], None
    for w, window in enumerate(windows):
        prev = track_window(
            str(site12_dir), METHOD, seg.seed, prev, parts, window, w == len(windows) - 1, bounds
        )
        results.append(prev)
    assert len(windows) >= 2 or window_s > seg.t_last - seg.t_first
    assert _key(segment_tracks(results)) == _key(whole.tracks)


@pytest.mark.parametrize(("window_s", "chunk_s"), [(7.0, 5.0), (31.5, 1e5)])
def test_window_and_chunk_sizes_keep_the_hash(
    site12_dir, small_archive, local_manifest, run_reprocess, tmp_path, window_s, chunk_s
):
    got = run_reprocess(
        site12_dir, small_archive, tmp_path / "o", window_s=window_s, chunk_s=chunk_s
    )
    assert (
        got["n_parts"] != local_manifest["n_parts"] or got["window_s"] != local_manifest["window_s"]
    )
    assert got["content_hash"] == local_manifest["content_hash"]


@pytest.mark.parametrize("chunk_s", [None, 0.15])
def test_parts_geolocate_as_one_batch(site12_dir, planned, geolocated, chunk_s):
    # Reference: build_fixes over every detection at once. 0.15 s chunks: parts of one
    # or two detections (a part of one goes another way through numpy: tasks.py).
    read, plan = planned
    site = site_at(str(site12_dir))
    if chunk_s is not None:
        plan = make_plan(read.table, list(plan.groups), chunk_s=chunk_s)
        assert min(len(p.rows) for p in plan.parts) == 1
        geolocated = run_local(plan, read.table, str(site12_dir), "raw-first").geo
    dets, _ = detections_of(read.table)
    fixes, _ = build_fixes(site, dets)
    whole = FixColumns.from_fixes(fixes, np.arange(len(dets))).sorted()
    parts = FixColumns.concat([g.fixes for g in geolocated]).sorted()
    assert np.array_equal(whole.det_id, parts.det_id)
    for name in ("t_s", "origin_enu", "direction_enu", "hit_offsets", "hits_enu", "hit_sigma_m",
                 "hit_cov_en_m2", "has_road"):  # fmt: skip
        assert np.array_equal(getattr(whole, name), getattr(parts, name)), name
    assert np.array_equal(whole.road_enu, parts.road_enu, equal_nan=True)


def test_quiet_gaps_make_the_segments(planned):
    read, plan = planned
    # three copies of two scenarios, 90 s apart: six segments per group that saw them
    assert {s.group for s in plan.segments} == {0, 1, 2, 3}
    again = make_plan(read.table, list(plan.groups), window_s=1.0, chunk_s=1.0)
    assert [(s.group, s.t_first, s.seed) for s in again.segments] == [
        (s.group, s.t_first, s.seed) for s in plan.segments
    ]
    for s in plan.segments:
        assert s.t_last - s.t_first < 300
