"""Archives: the Parquet layout, every reader, and a store's export read back."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest

from demtrack.core.errors import InputFileError
from demtrack.core.io.detections import write_detections_jsonl
from demtrack.core.tracking.types import Detection
from demtrack.reprocess.archive import ARCHIVE_SCHEMA, detections_of, write_archive
from demtrack.reprocess.sources import read_archive
from demtrack.reprocess.store_export import export_store, store_table
from demtrack.server.store.database import Store

T0 = 1_796_133_600.0  # 2026-12-01T14:00:00Z
SIZES = {"cam1": (1280, 720), "cam2": (1280, 720)}


def _detections(n: int = 200) -> list[Detection]:
    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        u, v = rng.uniform(0, 1200), rng.uniform(0, 650)
        out.append(
            Detection(
                T0 + 20.0 * i,  # over an hour: two partitions per sensor
                "cam1" if i % 2 else "cam2",
                (u, v, u + rng.uniform(1, 60), v + rng.uniform(1, 60)),
                "vehicle" if i % 5 else "human",
                None if i % 7 == 0 else float(rng.uniform(0.5, 1)),
                None if i % 4 else f"id{i}",
            )
        )
    return out


def _canonical(dets: list[Detection]) -> list[Detection]:
    order = sorted(range(len(dets)), key=lambda i: (dets[i].t_s, dets[i].sensor, i))
    return [dets[i] for i in order]


def test_jsonl_to_archive_and_back(tmp_path):
    dets = _detections()
    src = tmp_path / "d.jsonl"
    write_detections_jsonl(src, dets)
    from_file = read_archive(src, SIZES)
    assert from_file.table.num_rows == len(dets)
    n = write_archive(from_file.table, tmp_path / "arc")
    assert n == len(dets)
    # hive partitions by sensor and UTC hour
    parts = sorted(
        p.relative_to(tmp_path / "arc").as_posix() for p in (tmp_path / "arc").rglob("*.parquet")
    )
    assert parts == [
        "sensor=cam1/hour=2026-12-01T14/part-0.parquet",
        "sensor=cam1/hour=2026-12-01T15/part-0.parquet",
        "sensor=cam2/hour=2026-12-01T14/part-0.parquet",
        "sensor=cam2/hour=2026-12-01T15/part-0.parquet",
    ]
    back = read_archive(tmp_path / "arc", SIZES)
    assert back.table.equals(from_file.table)
    got, poses = detections_of(back.table)
    assert got == _canonical(dets)
    assert poses == {}


def test_csv_and_parquet_file_read_the_same(tmp_path):
    from demtrack.core.io.detections import write_detections_csv

    dets = _detections(50)
    write_detections_csv(tmp_path / "d.csv", dets)
    a = read_archive(tmp_path / "d.csv", SIZES)
    import pyarrow.parquet as pq

    pq.write_table(a.table, tmp_path / "d.parquet")
    b = read_archive(tmp_path / "d.parquet", SIZES)
    assert detections_of(a.table)[0] == detections_of(b.table)[0] == _canonical(dets)


def test_unknown_sensors_and_bad_rows_are_counted(tmp_path):
    dets = _detections(20)
    from demtrack.reprocess.archive import table_from_detections

    t = table_from_detections(dets)
    sensors = t["sensor"].to_pylist()
    sensors[0] = "ghost"
    t = t.set_column(t.schema.get_field_index("sensor"), "sensor", pa.array(sensors))
    u = t["u_min"].to_numpy().copy()
    u[1] = np.nan
    t = t.set_column(t.schema.get_field_index("u_min"), "u_min", pa.array(u))
    import pyarrow.parquet as pq

    pq.write_table(t, tmp_path / "x.parquet")
    got = read_archive(tmp_path / "x.parquet", SIZES)
    assert got.counts == {"unknown_sensor": 1, "nan": 1}
    assert got.table.num_rows == 18


def test_inline_poses_travel_with_their_detections(tmp_path):
    lines = [
        json.dumps(
            {
                "t": T0 + i,
                "sensor": "cam1",
                "bbox": [10, 10, 20, 30],
                "class": "human",
                "pan_deg": 10.0 + i,
                "tilt_deg": -5.0,
                "hfov_deg": 30.0,
            }
        )  # fmt: skip
        for i in range(3)
    ]
    (tmp_path / "p.jsonl").write_text("\n".join(lines) + "\n")
    table = read_archive(tmp_path / "p.jsonl", SIZES).table
    write_archive(table, tmp_path / "arc")
    _, poses = detections_of(read_archive(tmp_path / "arc", SIZES).table)
    assert poses == {i: (10.0 + i, -5.0, 30.0) for i in range(3)}


def test_store_export_round_trip(tmp_path):
    dets = _detections(120)
    store = Store(tmp_path / "s.sqlite3")
    store.insert_batch(dets[:70], {"n_records": 70, "accepted": 70}, None)
    store.insert_batch(dets[70:], {"n_records": 50, "accepted": 50}, None)
    stored = store.detections(limit=10_000)
    store.close()
    assert export_store(str(tmp_path / "s.sqlite3"), tmp_path / "arc") == len(dets)
    back = read_archive(tmp_path / "arc", SIZES).table
    # every stored detection, with its store id as seq
    by_seq = dict(zip(back["seq"].to_pylist(), detections_of(back)[0], strict=True))
    assert by_seq == dict(stored)
    # the store read directly (as a source) is the same table
    assert read_archive(tmp_path / "s.sqlite3", SIZES).table.equals(back)
    assert store_table(f"sqlite:///{tmp_path / 's.sqlite3'}").num_rows == len(dets)


def test_mistakes_are_input_errors(tmp_path):
    with pytest.raises(InputFileError, match="does not exist"):
        read_archive(tmp_path / "none.jsonl", SIZES)
    (tmp_path / "x.txt").write_text("")
    with pytest.raises(InputFileError, match="unknown archive kind"):
        read_archive(tmp_path / "x.txt", SIZES)
    with pytest.raises(InputFileError, match="does not exist"):
        read_archive(tmp_path / "none.sqlite3", SIZES)
    (tmp_path / "arc").mkdir()
    (tmp_path / "arc" / "f").write_text("x")
    with pytest.raises(InputFileError, match="not empty"):
        write_archive(
            pa.table({n: [] for n in ARCHIVE_SCHEMA.names}, schema=ARCHIVE_SCHEMA), tmp_path / "arc"
        )


def test_postgres_store_export_round_trip(postgres_url, tmp_path):
    from demtrack.server.store.opening import open_store

    dets = _detections(90)
    store = open_store(postgres_url)
    try:
        store.insert_batch(dets, {"n_records": 90, "accepted": 90}, None)
        stored = dict(store.detections(limit=10_000))
    finally:
        store.close()
    assert export_store(postgres_url, tmp_path / "arc") == len(dets)
    back = read_archive(tmp_path / "arc", SIZES).table
    assert dict(zip(back["seq"].to_pylist(), detections_of(back)[0], strict=True)) == stored
    assert read_archive(postgres_url, SIZES).table.equals(back)
