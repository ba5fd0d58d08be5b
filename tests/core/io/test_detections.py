import io
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.errors import InputFileError
from demtrack.core.io.detections import (
    REASONS,
    read_detection_records,
    read_detections,
    read_detections_csv,
    read_detections_jsonl,
    write_detections_csv,
    write_detections_jsonl,
)
from demtrack.core.tracking.types import Detection

SENSORS = {"cam0": (640, 480), "cam1": (1920, 1080)}


def _random_detections(n=25):
    rng = np.random.default_rng(0)
    out = []
    for k in range(n):
        sensor = "cam0" if k % 2 else "cam1"
        w, h = SENSORS[sensor]
        u0, v0 = rng.uniform(0, w / 2), rng.uniform(0, h / 2)
        box = (u0, v0, u0 + rng.uniform(1, w / 2 - 1), v0 + rng.uniform(1, h / 2 - 1))
        out.append(
            Detection(
                0.1 * k,
                sensor,
                box,
                "vehicle" if k % 3 else "human",
                None if k % 4 == 0 else float(rng.uniform()),
                None if k % 5 == 0 else f"id{k}",
            )
        )
    return out


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_round_trip(tmp_path, fmt):
    dets = _random_detections()
    path = tmp_path / f"d.{fmt}"
    (write_detections_csv if fmt == "csv" else write_detections_jsonl)(path, dets)
    got, report = read_detections(path, sensors=SENSORS)
    assert got == dets
    assert report.n_records == report.n_accepted == len(dets) and report.n_skipped == 0
    assert report.summary() == f"{len(dets)} of {len(dets)} detections accepted"


CSV_TEXT = """t,sensor,u_min,v_min,u_max,v_max,class,score,local_id
1.0,cam0,10,20,30,60,human,0.9,a
1.0,cam0,10,20,30,60,vehicle,,
oops,cam0,10,20,30,60,human,0.9,a
1.1,cam0,10,20,30
1.2,cam0,nan,20,30,60,human,,
1.3,cam0,10,20,30,60,dog,,

1.4,cam9,10,20,30,60,human,,
1.5,cam0,10,20,700,60,human,,
0.5,cam0,10,20,30,60,human,,
0.5,cam1,10,20,30,60,human,,
1.6,cam0,40,20,30,60,human,,
1.7,cam0,10,20,639.5,479.5,vehicle,1e-3,z
"""


def test_csv_validation_counts_every_reason_with_line_numbers():
    dets, rep = read_detections_csv(io.StringIO(CSV_TEXT), sensors=SENSORS)
    assert [d.t_s for d in dets] == [1.0, 1.0, 0.5, 1.7]
    assert dets[0] == Detection(1.0, "cam0", (10, 20, 30, 60), "human", 0.9, "a")
    assert dets[1].score is None and dets[1].local_id is None
    assert rep.counts == {
        "malformed": 3,
        "nan": 1,
        "unknown_class": 1,
        "unknown_sensor": 1,
        "outside_image": 1,
        "time_backwards": 1,
    }
    assert rep.n_records == 12 and rep.n_accepted == 4
    assert rep.n_accepted + rep.n_skipped == rep.n_records
    lines = {(e.line, e.reason) for e in rep.examples}
    assert lines == {
        (4, "malformed"),
        (5, "malformed"),
        (6, "nan"),
        (7, "unknown_class"),
        (9, "unknown_sensor"),
        (10, "outside_image"),
        (11, "time_backwards"),
        (13, "malformed"),
    }
    assert "skipped 8" in rep.summary() and "time_backwards=1" in rep.summary()


def test_without_known_sensors_only_structure_is_checked():
    dets, rep = read_detections_csv(io.StringIO(CSV_TEXT))
    assert rep.counts["unknown_sensor"] == rep.counts["outside_image"] == 0
    assert len(dets) == 6


def test_edge_tolerance_and_example_cap():
    text = "t,sensor,u_min,v_min,u_max,v_max,class\n" + "".join(
        f"{k},cam0,0,0,640,10,human\n" for k in range(8)
    )
    dets, rep = read_detections_csv(io.StringIO(text), sensors=SENSORS)
    assert len(dets) == 8  # u_max = W (pixel-edge convention) is within 1 px
    dets, rep = read_detections_csv(
        io.StringIO(text), sensors=SENSORS, edge_tolerance_px=0.0, max_examples=3
    )
    assert dets == [] and rep.counts["outside_image"] == 8 and len(rep.examples) == 3


def test_jsonl_validation():
    recs = [
        '{"t": 1.0, "sensor": "cam0", "bbox": [1, 2, 3, 4], "class": "human", "score": 0.5}',
        '{"t": 1.0, "sensor": "cam0", "bbox": [1, 2, 3, 4], "class": "vehicle", "local_id": 12}',
        "",
        "{not json",
        "[1, 2]",
        '{"t": 1.0, "sensor": "cam0", "bbox": [1, 2, 3], "class": "human"}',
        '{"t": 1.0, "sensor": "cam0", "class": "human"}',
        '{"t": true, "sensor": "cam0", "bbox": [1, 2, 3, 4], "class": "human"}',
        '{"t": NaN, "sensor": "cam0", "bbox": [1, 2, 3, 4], "class": "human"}',
        '{"t": 2.0, "sensor": "cam0", "bbox": [1, 2, 3, 4], "class": "person"}',
        '{"t": 2.0, "sensor": "x", "bbox": [1, 2, 3, 4], "class": "human"}',
        '{"t": 0.1, "sensor": "cam0", "bbox": [1, 2, 3, 4], "class": "human"}',
        '{"t": 2.0, "sensor": "cam0", "bbox": [1, 2, 3, 4000], "class": "human"}',
    ]
    dets, rep = read_detections_jsonl(io.StringIO("\n".join(recs) + "\n"), sensors=SENSORS)
    assert len(dets) == 2 and dets[1].local_id == "12" and dets[0].score == 0.5
    assert rep.counts == {
        "malformed": 5,
        "nan": 1,
        "unknown_class": 1,
        "unknown_sensor": 1,
        "outside_image": 1,
        "time_backwards": 1,
    }
    assert rep.n_records == 12
    assert [e.line for e in rep.examples if e.reason == "malformed"] == [4, 5, 6, 7, 8]


def test_whole_file_errors(tmp_path):
    with pytest.raises(InputFileError, match="lacks column"):
        read_detections_csv(io.StringIO("t,sensor,u_min\n1,a,2\n"))
    with pytest.raises(InputFileError, match="empty"):
        read_detections_csv(io.StringIO(""))
    with pytest.raises(InputFileError, match="cannot open"):
        read_detections(tmp_path / "missing.csv")
    with pytest.raises(InputFileError, match="unknown detection file type"):
        read_detections(tmp_path / "d.txt")


record = st.fixed_dictionaries(
    {
        "t": st.one_of(st.floats(allow_nan=True), st.text(max_size=3)),
        "sensor": st.sampled_from(["cam0", "cam1", "camX", ""]),
        "bbox": st.lists(st.floats(-10, 2000), min_size=3, max_size=5),
        "class": st.sampled_from(["human", "vehicle", "cat"]),
    }
)


@given(st.lists(st.one_of(record.map(json.dumps), st.text(max_size=20)), max_size=30))
@settings(max_examples=50, deadline=None)
def test_no_record_is_lost(lines):
    lines = [ln.replace("\n", " ").replace("\r", " ") for ln in lines]
    text = "\n".join(lines)
    dets, rep = read_detections_jsonl(io.StringIO(text), sensors=SENSORS)
    nonblank = sum(1 for ln in text.split("\n") if ln.strip())
    assert rep.n_records == nonblank
    assert rep.n_accepted == len(dets)
    assert rep.n_accepted + sum(rep.counts.values()) == rep.n_records
    assert set(rep.counts) == set(REASONS)


@given(st.lists(st.one_of(record, st.integers(), st.lists(st.integers(), max_size=2)), max_size=30))
@settings(max_examples=50, deadline=None)
def test_parsed_records_get_the_jsonl_answer(records):
    """Records checked as objects get the answer of the same records as JSON Lines."""
    text = "".join(json.dumps(r) + "\n" for r in records)
    want = read_detections_jsonl(io.StringIO(text), sensors=SENSORS, max_examples=100)
    got = read_detection_records(records, sensors=SENSORS, max_examples=100)
    assert got[0] == want[0]
    assert got[1] == want[1]


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.fixed_dictionaries(
            {
                "t": st.one_of(st.floats(allow_nan=True), st.integers(-100, 100)),
                "sensor": st.sampled_from(["cam1", "cam2", ""]),
                "bbox": st.lists(
                    st.one_of(st.floats(-10, 700), st.integers(-5, 700)), min_size=4, max_size=4
                ),
                "class": st.sampled_from(["vehicle", "human", "tree"]),
            },
            optional={
                "score": st.one_of(st.none(), st.floats(allow_nan=True), st.integers(0, 1)),
                "local_id": st.one_of(st.none(), st.text(max_size=3), st.integers(0, 9)),
            },
        ),
        max_size=12,
    )
)
def test_accepted_records_equal_the_checked_constructor(records: list[dict]) -> None:
    """The readers make detections without the constructor's checks: the same values and types."""
    dets, _ = read_detection_records(records, sensors={"cam1": (640, 480), "cam2": (640, 480)})
    for d in dets:
        made = Detection(d.t_s, d.sensor, d.bbox, d.cls, d.score, d.local_id)
        assert made == d
        assert [type(v) for v in vars(made).values()] == [type(v) for v in vars(d).values()]
        assert all(type(b) is float for b in d.bbox) and type(d.t_s) is float
