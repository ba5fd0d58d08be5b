"""Real time in detection files: UNIX seconds, ISO 8601 with a zone, a declared epoch."""

import io
import json
from datetime import UTC, datetime, timedelta, timezone

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.errors import InputFileError, QueryError, TimeFormatError
from demtrack.core.io.detections import (
    read_detection_records,
    read_detections,
    read_detections_csv,
    read_detections_jsonl,
    write_detections_jsonl,
)
from demtrack.core.io.times import format_utc, parse_iso_time, parse_time_value, unix_seconds

SENSORS = {"cam0": (640, 480)}
T0 = datetime(2026, 12, 1, 14, 30, tzinfo=UTC)
T0_S = 1796135400.0  # 2026-12-01T14:30:00Z, by hand: 20788 days * 86400 + 14.5 h
HEADER = "t,sensor,u_min,v_min,u_max,v_max,class,score,local_id\n"


def test_epoch_seconds_by_hand():
    assert T0_S == 20788 * 86400 + 14.5 * 3600
    assert unix_seconds(T0) == T0_S == T0.timestamp()
    assert parse_iso_time("2026-12-01T14:30:00Z") == T0_S
    assert parse_iso_time("2026-12-01T15:30:00+01:00") == T0_S
    assert parse_iso_time("2026-12-01 09:30:00.25-05:00") == T0_S + 0.25
    assert format_utc(T0_S) == "2026-12-01T14:30:00.000Z"
    assert format_utc(T0_S + 0.9996) == "2026-12-01T14:30:01.000Z"  # rounds up a second
    assert format_utc(T0_S, digits=0) == "2026-12-01T14:30:00Z"


@pytest.mark.parametrize(
    "text, words",
    [
        ("2026-12-01T14:30:00", "has no zone"),
        ("2026-12-01", "has no zone"),
        ("14:30:00Z", "ISO 8601 time with a zone"),
        ("yesterday", "ISO 8601 time with a zone"),
        ("2026-13-01T00:00:00Z", "ISO 8601 time with a zone"),
    ],
)
def test_bad_iso_times_refused_in_one_line(text, words):
    with pytest.raises(TimeFormatError, match=words) as err:
        parse_iso_time(text, "since")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("since")
    assert isinstance(err.value, QueryError) and isinstance(err.value, ValueError)


def test_parse_time_value_numbers_and_strings():
    assert parse_time_value(12.5) == 12.5
    assert parse_time_value("1796135400.5") == T0_S + 0.5
    assert parse_time_value("2026-12-01T14:30:00.5Z") == T0_S + 0.5
    for bad in (float("nan"), "inf", True, None):
        with pytest.raises(TimeFormatError):
            parse_time_value(bad)


@settings(max_examples=200, deadline=None)
@given(
    st.datetimes(
        min_value=datetime(1970, 1, 2), max_value=datetime(2100, 1, 1), timezones=st.just(UTC)
    ),
    st.integers(-14 * 60, 14 * 60),
)
def test_iso_round_trip_against_datetime(when, offset_min):
    """Any zone in, the same instant out (datetime is the oracle), to the microsecond."""
    zone = timezone(timedelta(minutes=offset_min))
    text = when.astimezone(zone).isoformat()
    t = parse_iso_time(text)
    want = (when - datetime(1970, 1, 1, tzinfo=UTC)) / timedelta(seconds=1)
    assert abs(t - want) < 1e-6
    back = datetime.fromisoformat(format_utc(t, 6).replace("Z", "+00:00"))
    assert abs((back - when) / timedelta(microseconds=1)) <= 1


def test_csv_epoch_header_makes_times_relative():
    text = "# written by a gateway\n# epoch: 2026-12-01T15:30:00+01:00\n" + HEADER
    text += "12.40,cam0,10,20,30,60,human,0.9,a\nbad,cam0,10,20,30,60,human,,\n"
    dets, rep = read_detections_csv(io.StringIO(text), sensors=SENSORS)
    assert [d.t_s for d in dets] == [T0_S + 12.4]
    assert rep.epoch_s == T0_S and not rep.relative
    assert rep.time_note == "times: seconds after the declared epoch 2026-12-01T14:30:00.000Z"
    # The skipped record keeps its real line number (comment lines counted).
    assert [(e.line, e.reason) for e in rep.examples] == [(5, "malformed")]


def test_csv_time_column_with_zones():
    text = HEADER.replace("t,", "time,", 1)
    text += "2026-12-01T14:30:12.4Z,cam0,10,20,30,60,human,,\n"
    text += "2026-12-01T14:30:13,cam0,10,20,30,60,human,,\n"
    dets, rep = read_detections_csv(io.StringIO(text), sensors=SENSORS)
    assert [d.t_s for d in dets] == [pytest.approx(T0_S + 12.4, abs=1e-6)]
    assert rep.counts["malformed"] == 1 and "has no zone" in rep.examples[0].message
    assert rep.time_note == ""


def test_csv_bad_epoch_and_double_time_columns_are_file_errors():
    with pytest.raises(InputFileError, match="line 1: epoch '2026-12-01T14:30:00' has no zone"):
        read_detections_csv(io.StringIO("# epoch: 2026-12-01T14:30:00\n" + HEADER))
    with pytest.raises(InputFileError, match="both a t and a time column"):
        read_detections_csv(io.StringIO("time," + HEADER))


def test_jsonl_epoch_record_iso_records_and_both_fields(tmp_path):
    lines = [
        {"epoch": "2026-12-01T14:30:00Z"},
        {"t": 1.5, "sensor": "cam0", "bbox": [10, 20, 30, 60], "class": "human"},
        {
            "time": "2026-12-01T14:30:02Z",
            "sensor": "cam0",
            "bbox": [10, 20, 30, 60],
            "class": "human",
        },
        {
            "t": 3,
            "time": "2026-12-01T14:30:03Z",
            "sensor": "cam0",
            "bbox": [10, 20, 30, 60],
            "class": "human",
        },
        {"time": 3.0, "sensor": "cam0", "bbox": [10, 20, 30, 60], "class": "human"},
    ]
    path = tmp_path / "d.jsonl"
    path.write_text("".join(json.dumps(x) + "\n" for x in lines))
    dets, rep = read_detections(path, sensors=SENSORS)
    assert [d.t_s for d in dets] == [T0_S + 1.5, T0_S + 2.0]
    assert rep.n_records == 4 and rep.counts["malformed"] == 2
    assert [e.message for e in rep.examples] == [
        "give t or time, not both",
        "time must be an ISO 8601 string, got 3.0",
    ]


def test_small_times_without_epoch_read_as_1970_and_said_relative(tmp_path):
    rec = {"t": 12.0, "sensor": "cam0", "bbox": [10, 20, 30, 60], "class": "human"}
    dets, rep = read_detection_records([rec], sensors=SENSORS)
    assert dets[0].t_s == 12.0 and rep.relative and "look relative" in rep.time_note
    dets, rep = read_detection_records([{**rec, "t": T0_S}], sensors=SENSORS)
    assert not rep.relative and rep.time_note == ""
    dets, rep = read_detection_records([rec], sensors=SENSORS, epoch_s=T0_S)
    assert dets[0].t_s == T0_S + 12.0 and rep.epoch_s == T0_S


def test_absolute_times_round_trip_through_jsonl():
    rec = {"t": T0_S + 0.123456, "sensor": "cam0", "bbox": [10, 20, 30, 60], "class": "human"}
    dets, _ = read_detection_records([rec])
    buf = io.StringIO()
    write_detections_jsonl(buf, dets)
    again, _ = read_detections_jsonl(io.StringIO(buf.getvalue()))
    assert again == dets and again[0].t_s == T0_S + 0.123456
