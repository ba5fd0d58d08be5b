"""Dask's job tasks geolocate their own detections: the fixes of the plan's parts."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.reprocess.engines import run_local
from demtrack.reprocess.fix_columns import FixColumns
from demtrack.reprocess.fused import job_rows, track_window_rows
from demtrack.reprocess.plan import make_plan
from demtrack.reprocess.run import ReprocessSettings, plan_run

METHOD = "raw-first"
FIELDS = ("det_id", "t_s", "origin_enu", "direction_enu", "hit_offsets", "hits_enu",
          "hit_sigma_m", "hit_cov_en_m2", "has_road", "score")  # fmt: skip


@pytest.fixture(scope="module")
def planned(site12_dir, small_archive):
    return plan_run(str(site12_dir), str(small_archive), ReprocessSettings(METHOD))


def test_segment_rows_partition_the_archive(planned):
    read, plan = planned
    rows = job_rows(plan, read.table)
    every = np.concatenate(rows.segments)
    assert np.array_equal(np.sort(every), np.arange(read.table.num_rows))
    assert rows.loose_parts == ()  # every sensor is in a group
    t = read.table["t_s"].to_numpy()
    for seg, r in zip(plan.segments, rows.segments, strict=True):
        assert t[r].min() == seg.t_first and t[r].max() == seg.t_last


def test_window_batches_geolocate_as_the_parts(site12_dir, planned):
    # 2 s windows: many batches where a sensor has one detection beside others' several
    # (numpy's single-row product path: the batch is geolocated sensor by sensor)
    read, plan = planned
    plan = make_plan(read.table, list(plan.groups), window_s=2.0)
    ref = FixColumns.concat(
        [g.fixes for g in run_local(plan, read.table, str(site12_dir), METHOD).geo]
    ).sorted()
    rows = job_rows(plan, read.table)
    t = read.table["t_s"].to_numpy()
    got, lone = [], 0
    for seg, seg_rows in zip(plan.segments, rows.segments, strict=True):
        for lo, hi in seg.windows:
            ids = seg_rows[(t[seg_rows] >= lo) & (t[seg_rows] < hi)]
            sensors = read.table["sensor"].take(ids).to_pylist()
            lone += len(set(sensors)) > 1 and min(sensors.count(s) for s in sensors) == 1
            geo, _ = track_window_rows(
                str(site12_dir), METHOD, seg.seed, None, read.table.take(ids), ids, (lo, hi),
                True, (seg.t_first, seg.t_last),
            )  # fmt: skip
            got.append(geo.fixes)
    assert lone > 0
    fused = FixColumns.concat(got).sorted()
    for name in FIELDS:
        assert np.array_equal(getattr(ref, name), getattr(fused, name), equal_nan=True), name
    assert np.array_equal(ref.road_enu, fused.road_enu, equal_nan=True)
