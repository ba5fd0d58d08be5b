"""Pose telemetry files: CSV and JSON Lines in, :class:`PoseSeries` per sensor out.

One record is one telemetry sample of one sensor (frames and angles:
:mod:`demtrack.core.camera.pose_series`)::

    sensor,t,pan_deg,tilt_deg,hfov_deg,roll_deg,e_m,n_m,u_m,yaw_deg,pitch_deg,platform_roll_deg

``sensor``, ``t`` (or ``time``), ``pan_deg`` and ``tilt_deg`` are required; the rest are
optional columns (an empty cell: not given). ``hfov_deg`` is the zoom as horizontal field
of view, ``roll_deg`` the camera's bank; ``e_m, n_m, u_m`` a moving platform's optical
centre (site frame, m; all three or none); ``yaw_deg, pitch_deg, platform_roll_deg`` its
attitude (all three or none). JSON Lines records carry the same names as fields::

    {"sensor": "ptz1", "time": "2026-12-01T14:30:12.40Z", "pan_deg": 31.2, "tilt_deg": -6.5,
     "hfov_deg": 22.0}

Times follow the detection files' rules (:mod:`demtrack.core.io.detections`): ``t`` is
UNIX seconds, or an ISO 8601 string with a zone (also in a ``time`` field or column); a
file with relative times declares its epoch (``# epoch: <ISO>`` before the CSV header,
``{"epoch": "<ISO>"}`` first in JSON Lines) and its numbers are seconds after it; a file
without one whose times are all before 2000 is read as seconds after 1970 and the report
says they look relative.

Every record is returned or counted under exactly one reason (:data:`POSE_REASONS`),
checked in this order, nothing else lost:

``malformed``
    unparsable line, missing or mistyped field, an ISO time without a zone, part of a
    position or attitude triple.
``nan``
    a NaN or infinite number.
``out_of_range``
    a tilt outside [-90, 90] or an hfov outside (0, 180) degrees.
``unknown_sensor``
    a sensor not among the known ones (only when ``sensors`` is given).
``time_backwards``
    a time earlier than the sensor's previous accepted sample.
``duplicate_time``
    a time equal to the sensor's previous accepted sample (a series' times increase
    strictly).
``mixed_fields``
    a record with optional parts (hfov, position, attitude) other than its sensor's
    first accepted record has: a series has them all or none.
"""

from __future__ import annotations

import csv
import functools
import itertools
import json
import os
from collections.abc import Collection, Iterable, Mapping
from pathlib import Path
from typing import Any

from ..camera.pose_series import PoseSample, PoseSeries
from ..errors import InputFileError, PoseError
from .detections import (
    RELATIVE_BEFORE_S,
    IngestIssue,
    IngestReport,
    Source,
    _csv_rows,
    _epoch,
    _float,
    _jsonl_lines,
    _open,
    _Skip,
    _time_of,
)

__all__ = [
    "POSE_COLUMNS",
    "POSE_REASONS",
    "PoseReadReport",
    "poses_from_detections",
    "read_pose_records",
    "read_poses",
    "read_poses_csv",
    "read_poses_jsonl",
    "write_poses_csv",
    "write_poses_jsonl",
]

POSE_COLUMNS = (
    "sensor", "t", "pan_deg", "tilt_deg", "hfov_deg", "roll_deg",
    "e_m", "n_m", "u_m", "yaw_deg", "pitch_deg", "platform_roll_deg",
)  # fmt: skip
POSE_REASONS = (
    "malformed", "nan", "out_of_range", "unknown_sensor", "time_backwards",
    "duplicate_time", "mixed_fields",
)  # fmt: skip
_POSITION = ("e_m", "n_m", "u_m")
_ATTITUDE = ("yaw_deg", "pitch_deg", "platform_roll_deg")


class PoseReadReport(IngestReport):
    """What a pose reader accepted and skipped (the fields of :class:`IngestReport`).

    ``counts`` holds every reason of :data:`POSE_REASONS`.
    """

    def summary(self) -> str:
        """One line: accepted count and non-zero skip counts."""
        parts = [f"{k}={v}" for k, v in self.counts.items() if v]
        tail = f", skipped {self.n_skipped} ({', '.join(parts)})" if parts else ""
        return f"{self.n_accepted} of {self.n_records} pose samples accepted{tail}"


class _PoseCollector:
    """Checks parsed pose records in file order and keeps the report."""

    def __init__(
        self, sensors: Collection[str] | None, max_examples: int, epoch_s: float | None = None
    ) -> None:
        self.sensors = None if sensors is None else set(sensors)
        self.max_examples = max_examples
        self.epoch_s = epoch_s
        self.counts = dict.fromkeys(POSE_REASONS, 0)
        self.examples: list[IngestIssue] = []
        self.samples: dict[str, list[PoseSample]] = {}
        self.n_records = 0

    def skip(self, line: int, reason: str, message: str) -> None:
        self.counts[reason] += 1
        if sum(1 for e in self.examples if e.reason == reason) < self.max_examples:
            self.examples.append(IngestIssue(line, reason, message))

    def offer(self, line: int, parse: Any) -> None:
        self.n_records += 1
        try:
            sensor, sample = self._check(parse())
        except _Skip as skip:
            self.skip(line, skip.reason, skip.message)
            return
        self.samples.setdefault(sensor, []).append(sample)

    def _check(self, rec: Mapping[str, Any]) -> tuple[str, PoseSample]:
        sensor = rec["sensor"]
        numbers = {k: v for k, v in rec.items() if k != "sensor" and v is not None}
        for key, value in numbers.items():
            if value != value or value in (float("inf"), float("-inf")):
                raise _Skip("nan", f"{key} is {value} for sensor {sensor}")
        pos = tuple(rec[k] for k in _POSITION)
        ypr = tuple(rec[k] for k in _ATTITUDE)
        for name, triple, keys in (("position", pos, _POSITION), ("attitude", ypr, _ATTITUDE)):
            if any(x is None for x in triple) and not all(x is None for x in triple):
                raise _Skip("malformed", f"a platform {name} needs all of {', '.join(keys)}")
        try:
            sample = PoseSample(
                rec["t"],
                rec["pan_deg"],
                rec["tilt_deg"],
                rec["hfov_deg"],
                0.0 if rec["roll_deg"] is None else rec["roll_deg"],
                None if pos[0] is None else pos,  # type: ignore[arg-type]
                None if ypr[0] is None else ypr,  # type: ignore[arg-type]
            )
        except PoseError as err:
            raise _Skip("out_of_range", str(err)) from None
        if self.sensors is not None and sensor not in self.sensors:
            raise _Skip("unknown_sensor", f"sensor {sensor!r} is not known")
        prior = self.samples.get(sensor)
        if prior:
            last = prior[-1]
            if sample.t_s < last.t_s:
                msg = f"t={sample.t_s} s is before {last.t_s} s for {sensor}"
                raise _Skip("time_backwards", msg)
            if sample.t_s == last.t_s:
                raise _Skip("duplicate_time", f"t={sample.t_s} s repeats for {sensor}")
            first = prior[0]
            for name in ("hfov_deg", "position_enu", "platform_ypr_deg"):
                if (getattr(first, name) is None) != (getattr(sample, name) is None):
                    raise _Skip(
                        "mixed_fields",
                        f"{name} {'missing' if getattr(sample, name) is None else 'given'} "
                        f"for {sensor}, unlike its first sample",
                    )
        return sensor, sample

    def result(self) -> tuple[dict[str, PoseSeries], PoseReadReport]:
        n_accepted = sum(len(v) for v in self.samples.values())
        relative = (
            self.epoch_s is None
            and n_accepted > 0
            and all(s.t_s < RELATIVE_BEFORE_S for v in self.samples.values() for s in v)
        )
        report = PoseReadReport(
            self.n_records,
            n_accepted,
            dict(self.counts),
            tuple(sorted(self.examples, key=lambda e: e.line)),
            self.epoch_s,
            relative,
        )
        return {k: PoseSeries.from_samples(v) for k, v in self.samples.items()}, report


def _record(get: Any, has: Any, epoch_s: float | None) -> dict[str, Any]:
    """The typed record from a field getter (CSV cell or JSON field)."""
    sensor = get("sensor")
    if not isinstance(sensor, str) or not sensor.strip():
        raise _Skip("malformed", f"sensor must be a non-empty string, got {sensor!r}")
    if has("t") and has("time"):
        raise _Skip("malformed", "give t or time, not both")
    t_name = "time" if has("time") else "t"
    if not has(t_name):
        raise _Skip("malformed", "missing field 't' (or 'time')")
    out: dict[str, Any] = {"sensor": sensor.strip(), "t": _time_of(get(t_name), t_name, epoch_s)}
    for key in POSE_COLUMNS[2:]:
        if key in ("pan_deg", "tilt_deg") and not has(key):
            raise _Skip("malformed", f"missing field {key!r}")
        out[key] = _float(get(key), key) if has(key) else None
    return out


def read_poses_csv(
    source: Source, *, sensors: Collection[str] | None = None, max_examples: int = 5
) -> tuple[dict[str, PoseSeries], PoseReadReport]:
    """Read a pose CSV (format in the module notes).

    Parameters
    ----------
    source : path or text file
    sensors : collection of str, optional
        Known sensor ids; when given, samples of others are skipped (``unknown_sensor``).
    max_examples : int
        Skipped records kept as examples, per reason.

    Returns
    -------
    poses : dict of str to PoseSeries
        One series per sensor, in time order.
    report : PoseReadReport

    Raises
    ------
    InputFileError
        If the file cannot be read or lacks a required column.
    """
    col = _PoseCollector(sensors, max_examples)
    with _open(source, "r") as fh:
        n_before = 0
        first = fh.readline()
        while first.lstrip().startswith("#"):
            n_before += 1
            key, sep, value = first.lstrip()[1:].partition(":")
            if sep and key.strip().lower() == "epoch":
                col.epoch_s = _epoch(value.strip(), f"pose CSV line {n_before}")
            first = fh.readline()
        if not first:
            raise InputFileError("pose CSV is empty (no header row)")
        reader = csv.reader(itertools.chain([first], fh))
        header = [h.strip() for h in next(reader)]
        missing = [c for c in ("sensor", "pan_deg", "tilt_deg") if c not in header]
        if "t" not in header and "time" not in header:
            missing.insert(1, "t (or time)")
        if missing:
            raise InputFileError(
                f"pose CSV lacks column(s) {', '.join(missing)}; header is {','.join(header)}"
            )
        pos = {name: i for i, name in enumerate(header)}
        for line, row in _csv_rows(reader, len(header), n_before, col):

            def get(name: str, row: list[str] = row) -> str:
                return row[pos[name]].strip()

            def has(name: str, row: list[str] = row) -> bool:
                return name in pos and bool(row[pos[name]].strip())

            col.offer(line, functools.partial(_record, get, has, col.epoch_s))
    return col.result()


def _object(obj: Any, epoch_s: float | None) -> dict[str, Any]:
    if not isinstance(obj, dict):
        raise _Skip("malformed", f"a record must be a JSON object, got {type(obj).__name__}")
    unknown = sorted(set(obj) - set(POSE_COLUMNS) - {"time"})
    if unknown:
        raise _Skip("malformed", f"unknown field(s) {', '.join(unknown)}")
    if "time" in obj and not isinstance(obj["time"], str):
        raise _Skip("malformed", f"time must be an ISO 8601 string, got {obj['time']!r}")
    return _record(obj.get, lambda k: obj.get(k) is not None, epoch_s)


def read_poses_jsonl(
    source: Source, *, sensors: Collection[str] | None = None, max_examples: int = 5
) -> tuple[dict[str, PoseSeries], PoseReadReport]:
    """Read a pose JSON Lines file; parameters and returns of :func:`read_poses_csv`."""
    col = _PoseCollector(sensors, max_examples)
    with _open(source, "r") as fh:
        for line_no, text in _jsonl_lines(fh, col, "pose"):
            col.offer(line_no, functools.partial(_json_text, text, col))
    return col.result()


def _json_text(text: str, col: _PoseCollector) -> dict[str, Any]:
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as err:
        raise _Skip("malformed", f"invalid JSON: {err.msg} at column {err.colno}") from None
    return _object(obj, col.epoch_s)


def read_pose_records(
    records: Iterable[Any],
    *,
    sensors: Collection[str] | None = None,
    max_examples: int = 5,
    epoch_s: float | None = None,
) -> tuple[dict[str, PoseSeries], PoseReadReport]:
    """Check already parsed JSON records (dicts) with the JSON Lines rules.

    An issue's ``line`` is the record's 1-based position; ``epoch_s`` (UNIX s) is the
    epoch of numeric ``t`` (None: they are UNIX seconds). For an HTTP batch of poses.
    """
    col = _PoseCollector(sensors, max_examples, epoch_s)
    for line_no, obj in enumerate(records, start=1):
        col.offer(line_no, functools.partial(_object, obj, epoch_s))
    return col.result()


def read_poses(
    path: str | os.PathLike[str], *, sensors: Collection[str] | None = None, max_examples: int = 5
) -> tuple[dict[str, PoseSeries], PoseReadReport]:
    """Read ``.csv`` or ``.jsonl`` / ``.ndjson`` pose telemetry, by file suffix."""
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        return read_poses_csv(path, sensors=sensors, max_examples=max_examples)
    if suffix in (".jsonl", ".ndjson"):
        return read_poses_jsonl(path, sensors=sensors, max_examples=max_examples)
    raise InputFileError(f"unknown pose file type {suffix!r} (use .csv or .jsonl)")


def _rows(poses: Mapping[str, PoseSeries]) -> list[dict[str, Any]]:
    """Every sample as a flat record, in time order (ties by sensor id)."""
    rows = []
    for sensor, series in poses.items():
        for s in series.samples():
            rec: dict[str, Any] = {
                "sensor": sensor, "t": s.t_s, "pan_deg": s.pan_deg, "tilt_deg": s.tilt_deg,
            }  # fmt: skip
            if s.hfov_deg is not None:
                rec["hfov_deg"] = s.hfov_deg
            if s.roll_deg != 0.0:
                rec["roll_deg"] = s.roll_deg
            if s.position_enu is not None:
                rec.update(zip(_POSITION, s.position_enu, strict=True))
            if s.platform_ypr_deg is not None:
                rec.update(zip(_ATTITUDE, s.platform_ypr_deg, strict=True))
            rows.append(rec)
    rows.sort(key=lambda r: (r["t"], r["sensor"]))
    return rows


def write_poses_csv(dest: Source, poses: Mapping[str, PoseSeries]) -> None:
    """Write pose series as CSV (every column of :data:`POSE_COLUMNS`; empty: not given)."""
    with _open(dest, "w") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(POSE_COLUMNS)
        for rec in _rows(poses):
            writer.writerow(
                [rec["sensor"]] + ["" if c not in rec else repr(rec[c]) for c in POSE_COLUMNS[1:]]
            )


def write_poses_jsonl(dest: Source, poses: Mapping[str, PoseSeries]) -> None:
    """Write pose series as JSON Lines (fields not given are left out)."""
    with _open(dest, "w") as fh:
        fh.write("".join(json.dumps(rec, allow_nan=False) + "\n" for rec in _rows(poses)))


def poses_from_detections(report: IngestReport) -> dict[str, PoseSeries]:
    """The inline poses of a detection read (``pan_deg``/``tilt_deg``/``hfov_deg`` fields).

    Several detections of one frame carry one pose: samples at a time already seen for
    the sensor are dropped (the first is kept), so each series' times increase strictly.
    Samples whose optional parts differ from the sensor's first are dropped too.
    """
    out = {}
    for sensor, samples in report.poses.items():
        kept: list[PoseSample] = []
        for s in samples:
            if kept and (
                s.t_s <= kept[-1].t_s or (s.hfov_deg is None) != (kept[0].hfov_deg is None)
            ):
                continue  # the same frame again, or a zoom where the first had none
            kept.append(s)
        out[sensor] = PoseSeries.from_samples(kept)
    return out
