"""Detection archives: Parquet partitioned by sensor and hour, and every reader.

The layout (pyarrow dataset, hive partitioning)::

    DIR/sensor=cam1/hour=2026-12-01T14/part-0.parquet

one row per detection with the detection record's fields: ``seq`` (int64, the record's
place in the source: a store's detection id, a file's record order), ``t_s`` (UNIX
seconds UTC), ``u_min``, ``v_min``, ``u_max``, ``v_max`` (pixels, demtrack's convention),
``cls``, ``score`` and ``local_id`` (nullable), and the inline pose ``pan_deg``,
``tilt_deg``, ``hfov_deg`` (nullable; see :mod:`demtrack.core.io.detections`). ``sensor``
and ``hour`` (UTC, ``YYYY-MM-DDTHH``) are the partition keys.

:func:`demtrack.reprocess.sources.read_archive` reads any source - a ``.jsonl`` /
``.csv`` detection file, a ``.parquet`` file or dataset folder, a store's SQLite file or
a database URL - into one table in canonical order: by time, then sensor, then ``seq``.
A row's place in that order is its detection id (``det_id``) throughout reprocessing.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from demtrack.core.errors import InputFileError
from demtrack.core.tracking.types import Detection

__all__ = [
    "ARCHIVE_SCHEMA",
    "PARTITIONING",
    "ArchiveRead",
    "checked_table",
    "detections_of",
    "is_database",
    "parquet_table",
    "read_detection_file",
    "table_from_detections",
    "write_archive",
]

#: Columns of an archive row (``sensor`` and ``hour`` are partition keys on disk).
ARCHIVE_SCHEMA = pa.schema(
    [
        ("seq", pa.int64()),
        ("t_s", pa.float64()),
        ("sensor", pa.string()),
        ("u_min", pa.float64()),
        ("v_min", pa.float64()),
        ("u_max", pa.float64()),
        ("v_max", pa.float64()),
        ("cls", pa.string()),
        ("score", pa.float64()),
        ("local_id", pa.string()),
        ("pan_deg", pa.float64()),
        ("tilt_deg", pa.float64()),
        ("hfov_deg", pa.float64()),
    ]
)

#: Hive partitioning by sensor and UTC hour, both read back as strings.
PARTITIONING = ds.partitioning(
    pa.schema([("sensor", pa.string()), ("hour", pa.string())]), flavor="hive"
)

_DB_SUFFIXES = (".sqlite3", ".sqlite", ".db")


@dataclass(frozen=True)
class ArchiveRead:
    """An archive read into memory.

    Attributes
    ----------
    table : pyarrow.Table
        :data:`ARCHIVE_SCHEMA` columns in canonical order (time, sensor, seq).
    counts : dict of str to int
        Records skipped, by reason (``unknown_sensor``, and a file reader's reasons).
    n_records : int
        Records in the source.
    """

    table: pa.Table
    counts: dict[str, int] = field(default_factory=dict)
    n_records: int = 0

    def summary(self) -> str:
        """One line: records read, accepted, skipped by reason."""
        skipped = ", ".join(f"{k} {v}" for k, v in sorted(self.counts.items()) if v)
        return f"archive: {self.n_records} record(s), {self.table.num_rows} accepted" + (
            f" (skipped: {skipped})" if skipped else ""
        )


def _hour(t_s: np.ndarray) -> list[str]:
    """UTC hour keys ``YYYY-MM-DDTHH`` of UNIX seconds."""
    hours = np.floor(np.asarray(t_s, dtype=np.float64) / 3600.0).astype(np.int64)
    keys: dict[int, str] = {}
    for h in np.unique(hours).tolist():
        keys[h] = datetime.fromtimestamp(h * 3600, tz=UTC).strftime("%Y-%m-%dT%H")
    return [keys[h] for h in hours.tolist()]


def table_from_detections(
    detections: Sequence[Detection],
    poses: Mapping[int, tuple[float, float, float | None]] | None = None,
    seq: Sequence[int] | None = None,
) -> pa.Table:
    """Archive rows of ``detections`` (``poses``: inline pose by index; ``seq``: default 0..)."""
    poses = poses or {}
    n = len(detections)
    pose = [poses.get(i) for i in range(n)]
    cols: dict[str, Any] = {
        "seq": list(range(n)) if seq is None else [int(s) for s in seq],
        "t_s": [d.t_s for d in detections],
        "sensor": [d.sensor for d in detections],
        "u_min": [d.bbox[0] for d in detections],
        "v_min": [d.bbox[1] for d in detections],
        "u_max": [d.bbox[2] for d in detections],
        "v_max": [d.bbox[3] for d in detections],
        "cls": [d.cls for d in detections],
        "score": [d.score for d in detections],
        "local_id": [d.local_id for d in detections],
        "pan_deg": [p[0] if p else None for p in pose],
        "tilt_deg": [p[1] if p else None for p in pose],
        "hfov_deg": [p[2] if p else None for p in pose],
    }
    return pa.table(cols, schema=ARCHIVE_SCHEMA)


def write_archive(table: pa.Table, out_dir: str | os.PathLike[str]) -> int:
    """Write archive rows as Parquet partitioned by sensor and hour; returns the row count.

    ``out_dir`` must be missing or empty (an archive is written whole, never appended to).
    """
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()):
        raise InputFileError(f"archive folder {out} is not empty: choose a new one")
    table = table.select(ARCHIVE_SCHEMA.names).cast(ARCHIVE_SCHEMA)
    table = table.append_column("hour", pa.array(_hour(table["t_s"].to_numpy()), pa.string()))
    table = table.sort_by([("t_s", "ascending"), ("sensor", "ascending"), ("seq", "ascending")])
    ds.write_dataset(
        table,
        out,
        format="parquet",
        partitioning=PARTITIONING,
        basename_template="part-{i}.parquet",
        existing_data_behavior="overwrite_or_ignore",
        max_rows_per_group=1 << 20,
    )
    return table.num_rows


def read_detection_file(path: Path, sensors: Mapping[str, tuple[int, int]]) -> ArchiveRead:
    """A detection file read with the file readers' checks (:mod:`demtrack.core.io.detections`)."""
    from demtrack.core.io.detections import read_detections

    detections, report = read_detections(path, sensors=sensors)
    # The readers give inline poses per sensor in record order; match them to records.
    queues: dict[str, list[Any]] = {s: list(v) for s, v in report.poses.items()}
    poses: dict[int, tuple[float, float, float | None]] = {}
    heads = dict.fromkeys(queues, 0)
    for i, det in enumerate(detections):
        q = queues.get(det.sensor)
        k = heads.get(det.sensor, 0)
        if q and k < len(q) and q[k].t_s == det.t_s:
            poses[i] = (q[k].pan_deg, q[k].tilt_deg, q[k].hfov_deg)
            heads[det.sensor] = k + 1
    table = table_from_detections(detections, poses)
    counts = {k: v for k, v in report.counts.items() if v}
    return ArchiveRead(_canonical(table), counts, report.n_records)


def parquet_table(path: Path) -> pa.Table:
    """A Parquet file's or dataset folder's rows as :data:`ARCHIVE_SCHEMA` (missing: null)."""
    if path.is_dir():
        dataset = ds.dataset(path, format="parquet", partitioning=PARTITIONING)
        table = dataset.to_table()
    else:
        table = pq.read_table(path)
    missing = [n for n in ("t_s", "sensor", "u_min", "v_min", "u_max", "v_max", "cls")
               if n not in table.column_names]  # fmt: skip
    if missing:
        raise InputFileError(f"{path}: not a detection archive (no column {missing[0]!r})")
    n = table.num_rows
    for name in ARCHIVE_SCHEMA.names:
        if name not in table.column_names:
            fill = pa.array(np.arange(n), pa.int64()) if name == "seq" else pa.nulls(n)
            table = table.append_column(name, fill.cast(ARCHIVE_SCHEMA.field(name).type))
    return table.select(ARCHIVE_SCHEMA.names).cast(ARCHIVE_SCHEMA)


def checked_table(table: pa.Table, sensors: Mapping[str, tuple[int, int]]) -> ArchiveRead:
    """Rows of known sensors and classes with finite, ordered boxes (the rest counted)."""
    counts: dict[str, int] = {}
    n = table.num_rows
    box = [table[c].to_numpy(zero_copy_only=False) for c in ("u_min", "v_min", "u_max", "v_max")]
    t = table["t_s"].to_numpy(zero_copy_only=False)
    finite = np.isfinite(t) & np.logical_and.reduce([np.isfinite(b) for b in box])
    ordered = (box[0] <= box[2]) & (box[1] <= box[3])
    cls_ok = pc.is_in(table["cls"], pa.array(["vehicle", "human"])).to_numpy(zero_copy_only=False)
    known = pc.is_in(table["sensor"], pa.array(sorted(sensors))).to_numpy(zero_copy_only=False)
    keep = np.ones(n, bool)
    for reason, ok in (
        ("malformed", ordered | ~finite),
        ("nan", finite),
        ("unknown_class", cls_ok),
        ("unknown_sensor", known),
    ):
        bad = keep & ~ok
        if bad.any():
            counts[reason] = int(bad.sum())
        keep &= ok
    return ArchiveRead(_canonical(table.filter(pa.array(keep))), counts, n)


def _canonical(table: pa.Table) -> pa.Table:
    return table.sort_by([("t_s", "ascending"), ("sensor", "ascending"), ("seq", "ascending")])


def is_database(source: str) -> bool:
    """Whether ``source`` names a store: a database URL or a SQLite file."""
    return "://" in source or Path(source).suffix.lower() in _DB_SUFFIXES


def detections_of(
    table: pa.Table,
) -> tuple[list[Detection], dict[int, tuple[float, float, float | None]]]:
    """Detection values of archive rows, and their inline poses by row."""
    cols = {n: table[n].to_pylist() for n in ARCHIVE_SCHEMA.names}
    dets = [
        Detection(t, s, (a, b, c, d), k, sc, lid)  # type: ignore[arg-type]
        for t, s, a, b, c, d, k, sc, lid in zip(
            cols["t_s"], cols["sensor"], cols["u_min"], cols["v_min"], cols["u_max"],
            cols["v_max"], cols["cls"], cols["score"], cols["local_id"], strict=True,
        )
    ]  # fmt: skip
    poses = {
        i: (p, q, h)
        for i, (p, q, h) in enumerate(
            zip(cols["pan_deg"], cols["tilt_deg"], cols["hfov_deg"], strict=True)
        )
        if p is not None and q is not None and not (math.isnan(p) or math.isnan(q))
    }
    return dets, poses
