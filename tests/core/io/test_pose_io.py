"""Pose telemetry files, and inline poses in detection records."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.camera.pose_series import PoseSample, PoseSeries
from demtrack.core.errors import InputFileError
from demtrack.core.io.detections import (
    read_detection_records,
    read_detections_csv,
    read_detections_jsonl,
)
from demtrack.core.io.pose_io import (
    POSE_REASONS,
    poses_from_detections,
    read_pose_records,
    read_poses,
    read_poses_csv,
    read_poses_jsonl,
    write_poses_csv,
    write_poses_jsonl,
)
from demtrack.core.io.times import parse_iso_time

T0 = 1.8e9


def series_set():
    t = T0 + 0.1 * np.arange(5)
    ptz = PoseSeries.from_arrays(t, [179.5, -179.0, -178.25, 10.0, 11.0], [-5, -5, -4, -3, 0])
    ptz = PoseSeries.from_arrays(
        t, ptz.at(t).pan_deg, ptz.at(t).tilt_deg, hfov_deg=[30, 29, 28, 27, 26.5]
    )
    drone = PoseSeries.from_arrays(
        t + 0.05,
        np.zeros(5),
        -np.arange(5.0),
        roll_deg=[0, 0.5, 1, 0, 0],
        position_enu=np.column_stack([np.arange(5.0), 2 * np.arange(5.0), 100 + np.zeros(5)]),
        platform_ypr_deg=np.column_stack([np.full(5, 270.0 - 360), np.ones(5), -np.ones(5)]),
    )
    return {"ptz": ptz, "drone": drone}


@pytest.mark.parametrize(
    ("write", "read", "suffix"),
    [(write_poses_csv, read_poses_csv, ".csv"), (write_poses_jsonl, read_poses_jsonl, ".jsonl")],
)
def test_round_trip(tmp_path, write, read, suffix):
    poses = series_set()
    path = tmp_path / f"poses{suffix}"
    write(path, poses)
    got, report = read(path)
    assert report.n_accepted == report.n_records == 10 and report.n_skipped == 0
    assert not report.relative and report.epoch_s is None
    for sid, series in poses.items():
        assert got[sid].samples() == series.samples()
    again, _ = read_poses(path)
    assert again["drone"].samples() == poses["drone"].samples()


def test_csv_with_epoch_iso_times_and_every_reason():
    text = "\n".join(
        [
            "# epoch: 2026-12-01T14:30:00Z",
            "sensor,t,pan_deg,tilt_deg,hfov_deg,e_m,n_m,u_m",
            "a,0.0,1,2,30,,,",
            "a,0.1,1,2,30,,,",
            "a,x,1,2,30,,,",  # malformed
            "a,0.2,nan,2,30,,,",  # nan
            "a,0.3,1,95,30,,,",  # out_of_range (tilt)
            "zz,0.3,1,2,30,,,",  # unknown_sensor
            "a,0.05,1,2,30,,,",  # time_backwards
            "a,0.1,1,2,30,,,",  # duplicate_time
            "a,0.4,1,2,,,,",  # mixed_fields (no hfov, the first had one)
            "a,0.5,1,2,30,1,2,",  # malformed: half a position
            "a,2026-12-01T14:30:01.5Z,1,2,30,,,",
            "a,2026-12-01T14:30:02,1,2,30,,,",  # malformed: no zone
            "b,0.0,3,4,,,,",
        ]
    )
    got, rep = read_poses_csv(io.StringIO(text), sensors={"a", "b"})
    epoch = parse_iso_time("2026-12-01T14:30:00Z")
    assert rep.epoch_s == epoch
    np.testing.assert_allclose(got["a"].t_s - epoch, [0.0, 0.1, 1.5], atol=1e-6)
    assert len(got["b"]) == 1
    assert rep.counts == {
        "malformed": 3, "nan": 1, "out_of_range": 1, "unknown_sensor": 1,
        "time_backwards": 1, "duplicate_time": 1, "mixed_fields": 1,
    }  # fmt: skip
    assert list(rep.counts) == list(POSE_REASONS)
    assert rep.n_records == 13 and rep.n_accepted == 4
    assert all("\n" not in e.message for e in rep.examples)
    assert {e.line for e in rep.examples if e.reason == "mixed_fields"} == {11}
    assert "4 of 13 pose samples accepted" in rep.summary()


def test_jsonl_epoch_record_and_relative_times():
    lines = [
        json.dumps({"epoch": "2026-12-01T15:30:00+01:00"}),
        json.dumps({"sensor": "a", "t": 1.0, "pan_deg": 5, "tilt_deg": -1}),
        json.dumps({"sensor": "a", "time": "2026-12-01T14:30:02Z", "pan_deg": 6, "tilt_deg": -1}),
        "{not json",
        json.dumps({"sensor": "a", "t": 3.0, "pan_deg": 6, "tilt_deg": -1, "zoom": 3}),
        json.dumps({"sensor": "a", "t": 4.0, "pan_deg": True, "tilt_deg": -1}),
    ]
    got, rep = read_poses_jsonl(io.StringIO("\n".join(lines)))
    epoch = parse_iso_time("2026-12-01T14:30:00Z")
    np.testing.assert_allclose(got["a"].t_s - epoch, [1.0, 2.0])
    assert rep.counts["malformed"] == 3
    # No epoch, small numbers: read as seconds after 1970 and said to look relative.
    got, rep = read_poses_jsonl(io.StringIO(lines[1]))
    assert got["a"].t_s[0] == 1.0 and rep.relative and "look relative" in rep.time_note


def test_records_of_a_batch_and_file_errors(tmp_path):
    got, rep = read_pose_records(
        [{"sensor": "a", "t": 1.0, "pan_deg": 1, "tilt_deg": 0}, "x"], epoch_s=T0
    )
    assert got["a"].t_s[0] == T0 + 1.0 and rep.counts["malformed"] == 1
    assert rep.examples[0].line == 2
    with pytest.raises(InputFileError, match="lacks column"):
        read_poses_csv(io.StringIO("sensor,t,pan_deg\na,1,2\n"))
    with pytest.raises(InputFileError, match="unknown pose file type"):
        read_poses(tmp_path / "p.txt")
    with pytest.raises(InputFileError, match="cannot open"):
        read_poses(tmp_path / "missing.csv")


def test_inline_poses_in_detection_records():
    csv_text = "\n".join(
        [
            "t,sensor,u_min,v_min,u_max,v_max,class,pan_deg,tilt_deg,hfov_deg",
            f"{T0},ptz,1,2,30,40,human,10.5,-3,25",
            f"{T0},ptz,50,2,80,40,human,10.5,-3,25",  # the same frame: one pose
            f"{T0 + 0.1},ptz,1,2,30,40,human,11,-3.5,24",
            f"{T0 + 0.1},cam,1,2,30,40,human,,,",  # no pose
            f"{T0 + 0.2},ptz,1,2,30,40,human,12,,",  # half a pose
            f"{T0 + 0.3},ptz,1,2,30,40,human,12,nan,",  # nan
        ]
    )
    dets, rep = read_detections_csv(io.StringIO(csv_text))
    assert len(dets) == 4 and rep.counts["malformed"] == 1 and rep.counts["nan"] == 1
    assert set(rep.poses) == {"ptz"} and len(rep.poses["ptz"]) == 3
    series = poses_from_detections(rep)
    assert series["ptz"].samples() == [
        PoseSample(T0, 10.5, -3.0, 25.0),
        PoseSample(T0 + 0.1, 11.0, -3.5, 24.0),
    ]
    jsonl = "\n".join(
        json.dumps({"t": T0, "sensor": "ptz", "bbox": [1, 2, 3, 4], "class": "vehicle", **extra})
        for extra in ({"pan_deg": 1, "tilt_deg": 2}, {"pan_deg": 1, "tilt_deg": 100})
    )
    dets, rep = read_detections_jsonl(io.StringIO(jsonl))
    assert len(dets) == 1 and rep.counts["malformed"] == 1
    assert rep.poses["ptz"] == (PoseSample(T0, 1.0, 2.0),)
    # The server's path: parsed records, same rules; records without a pose are as before.
    dets, rep = read_detection_records(
        [{"t": T0, "sensor": "c", "bbox": [1, 2, 3, 4], "class": "human"}]
    )
    assert len(dets) == 1 and rep.poses == {}


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(st.floats(1e-6, 100.0), min_size=1, max_size=8),
    pans=st.lists(st.floats(-1e4, 1e4), min_size=9, max_size=9),
    tilts=st.lists(st.floats(-90, 90), min_size=9, max_size=9),
    hfovs=st.lists(st.floats(0.01, 179.99), min_size=9, max_size=9),
    jsonl=st.booleans(),
)
def test_property_files_round_trip_exactly(steps, pans, tilts, hfovs, jsonl):
    t = T0 + np.concatenate([[0.0], np.cumsum(steps)])
    n = len(t)
    if np.any(np.diff(t) <= 0):
        return  # steps below the float spacing at 1.8e9 s collapse
    poses = {"s": PoseSeries.from_arrays(t, pans[:n], tilts[:n], hfov_deg=hfovs[:n])}
    buf = io.StringIO()
    (write_poses_jsonl if jsonl else write_poses_csv)(buf, poses)
    buf.seek(0)
    got, rep = (read_poses_jsonl if jsonl else read_poses_csv)(buf)
    assert rep.n_skipped == 0 and got["s"].samples() == poses["s"].samples()
