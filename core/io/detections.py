"""Detection files: reading CSV and JSON Lines with a report of what was skipped.

Two formats hold the same records, one detection per record. Boxes are pixels in
demtrack's convention (``(0, 0)`` is the centre of the top-left pixel, so an image of
width ``W`` spans ``u in [-0.5, W - 0.5]``).

Times are UTC. A record's time is either ``t``, a number of seconds, or an ISO 8601
string with a zone (in ``t`` or in a ``time`` field/column instead of ``t``:
``2026-12-01T14:32:05.250Z``, ``2026-12-01T15:32:05.25+01:00``). A number is UNIX
seconds, unless the file declares an epoch, and then it is seconds after that epoch (a
*relative* file): in CSV a comment line before the header, ``# epoch: 2026-12-01T14:30:00Z``;
in JSON Lines a first record holding only the epoch, ``{"epoch": "2026-12-01T14:30:00Z"}``.
An ISO time without a zone is refused (``malformed``). A file without an epoch whose
numbers are all small (before 2000-01-01 as UNIX seconds) is still read, as seconds after
1970-01-01T00:00:00Z, and the report says its times look relative
(:attr:`IngestReport.relative`).

CSV (UTF-8, comma-separated, a header row naming the columns, in any order; extra columns
are ignored)::

    # epoch: 2026-12-01T14:30:00Z
    t,sensor,u_min,v_min,u_max,v_max,class,score,local_id
    12.40,cam0,311.0,208.5,352.0,290.0,human,0.91,17
    12.40,cam1,80,40,160,95,vehicle,,

``score`` and ``local_id`` are optional columns, and an empty cell means "none".

JSON Lines (UTF-8, one JSON object per line; blank lines are ignored)::

    {"time": "2026-12-01T14:30:12.4Z", "sensor": "cam0", "bbox": [311.0, 208.5, 352.0, 290.0],
     "class": "human", "score": 0.91, "local_id": "17"}

(one line in the file); ``score`` and ``local_id`` may be absent or null; a numeric
``local_id`` is kept as its decimal string.

``class`` is ``vehicle`` or ``human``.

Inline pose (a PTZ camera that stamps its pose on each detection): optional fields or
columns ``pan_deg``, ``tilt_deg`` (both or neither) and ``hfov_deg`` (with them), in the
sense of :mod:`demtrack.core.camera.pose_series`. The reader hands them back as pose
samples of the record's sensor and time (:attr:`IngestReport.poses`;
:func:`demtrack.core.io.pose_io.poses_from_detections` makes series of them). A record
with half a pose, or one out of range, is ``malformed``; a NaN in one is ``nan``.

Every record is either returned or counted under exactly one reason, checked in this
order:

``malformed``
    unparsable line, missing or mistyped field, wrong box length, ``u_min > u_max`` or
    ``v_min > v_max``.
``nan``
    a NaN or infinite number.
``unknown_class``
    a class other than ``vehicle`` / ``human``.
``unknown_sensor``
    a sensor not among the known ones (only when ``sensors`` is given).
``outside_image``
    a box reaching beyond the image by more than ``edge_tolerance_px`` (only when
    ``sensors`` is given).
``time_backwards``
    a time earlier than the previous accepted record of the same sensor (equal is fine).
"""

from __future__ import annotations

import csv
import functools
import io
import itertools
import json
import math
import os
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from ..camera.pose_series import PoseSample
from ..errors import InputFileError, PoseError, TimeFormatError
from ..tracking.types import CLASSES, Detection
from .times import format_utc, parse_iso_time

__all__ = [
    "CSV_COLUMNS",
    "POSE_FIELDS",
    "REASONS",
    "RELATIVE_BEFORE_S",
    "IngestIssue",
    "IngestReport",
    "read_detection_records",
    "read_detections",
    "read_detections_csv",
    "read_detections_jsonl",
    "write_detections_csv",
    "write_detections_jsonl",
]

#: CSV columns written; the first seven are required (``time`` may stand for ``t``).
CSV_COLUMNS = ("t", "sensor", "u_min", "v_min", "u_max", "v_max", "class", "score", "local_id")
#: Optional inline pose columns / fields of a detection record.
POSE_FIELDS = ("pan_deg", "tilt_deg", "hfov_deg")
#: Times before this (UNIX seconds: 2000-01-01T00:00:00Z) in a file without an epoch look
#: like session seconds: the report says so.
RELATIVE_BEFORE_S = 946684800.0
#: Reasons a record is skipped, in the order they are checked.
REASONS = ("malformed", "nan", "unknown_class", "unknown_sensor", "outside_image", "time_backwards")

Source = str | os.PathLike[str] | IO[str]


@dataclass(frozen=True)
class IngestIssue:
    """One skipped record.

    Parameters
    ----------
    line : int
        1-based line number in the file.
    reason : str
        One of :data:`REASONS`.
    message : str
        What was wrong, in one line.
    """

    line: int
    reason: str
    message: str


@dataclass(frozen=True)
class IngestReport:
    """What a reader accepted and skipped.

    Parameters
    ----------
    n_records : int
        Records seen (data lines; header and blank lines excluded).
    n_accepted : int
        Records returned.
    counts : dict of str to int
        Skipped records per reason (every reason present, possibly 0).
    examples : tuple of IngestIssue
        The first few skipped records of each reason, in file order.
    epoch_s : float or None
        The epoch the file declared (UNIX seconds, UTC), None when it declared none.
    relative : bool
        No epoch was declared and every accepted time is before 2000-01-01 as UNIX
        seconds: the times were read as seconds after 1970-01-01T00:00:00Z, and are
        most likely session seconds.
    poses : dict of str to tuple of PoseSample
        The inline poses of accepted records, per sensor in record order (several
        detections of one frame repeat one pose); empty when no record has one.
    """

    n_records: int
    n_accepted: int
    counts: dict[str, int] = field(default_factory=dict)
    examples: tuple[IngestIssue, ...] = ()
    epoch_s: float | None = None
    relative: bool = False
    poses: dict[str, tuple[PoseSample, ...]] = field(default_factory=dict)

    @property
    def n_skipped(self) -> int:
        """Records skipped (``n_records - n_accepted``)."""
        return sum(self.counts.values())

    def summary(self) -> str:
        """One line: accepted count and non-zero skip counts."""
        parts = [f"{k}={v}" for k, v in self.counts.items() if v]
        tail = f", skipped {self.n_skipped} ({', '.join(parts)})" if parts else ""
        return f"{self.n_accepted} of {self.n_records} detections accepted{tail}"

    @property
    def time_note(self) -> str:
        """One line saying what the times are when not plain UTC clock times (else ``""``)."""
        if self.epoch_s is not None:
            return f"times: seconds after the declared epoch {format_utc(self.epoch_s)}"
        if self.relative:
            return (
                "times look relative (no epoch declared, all before 2000):"
                " read as seconds after 1970-01-01T00:00:00Z; declare the epoch"
                " ('# epoch: <ISO 8601>' in CSV, {\"epoch\": ...} first in JSON Lines)"
            )
        return ""


class _Skip(Exception):
    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason
        self.message = message


class _Collector:
    """Validates parsed records in file order and keeps the report."""

    def __init__(
        self,
        sensors: Mapping[str, tuple[int, int]] | None,
        max_examples: int,
        edge_tolerance_px: float,
        epoch_s: float | None = None,
    ) -> None:
        self.epoch_s = epoch_s
        self.sensors = sensors
        self.max_examples = max_examples
        self.tol = edge_tolerance_px
        self.counts = dict.fromkeys(REASONS, 0)
        self.examples: list[IngestIssue] = []
        self.accepted: list[Detection] = []
        self.poses: dict[str, list[PoseSample]] = {}
        self.last_t: dict[str, float] = {}
        self.n_records = 0

    def skip(self, line: int, reason: str, message: str) -> None:
        self.counts[reason] += 1
        if sum(1 for e in self.examples if e.reason == reason) < self.max_examples:
            self.examples.append(IngestIssue(line, reason, message))

    def offer(self, line: int, parse: Callable[[], Mapping[str, Any]]) -> None:
        """Add the record ``parse()`` makes, or count the reason it refuses (``_Skip``)."""
        try:
            rec = parse()
        except _Skip as skip:
            self.n_records += 1
            self.skip(line, skip.reason, skip.message)
            return
        self.add(line, rec)

    def add(self, line: int, rec: Mapping[str, Any]) -> None:
        """Check one record's values (already typed) and accept or skip it."""
        self.n_records += 1
        try:
            self.accepted.append(self._check(rec))
        except _Skip as skip:
            self.skip(line, skip.reason, skip.message)

    def _check(self, rec: Mapping[str, Any]) -> Detection:
        t, box, score = rec["t"], rec["bbox"], rec["score"]
        pose = rec.get("pose")
        numbers = [t, *box] + ([score] if score is not None else [])
        if not all(math.isfinite(x) for x in numbers):
            raise _Skip("nan", f"non-finite number in t={t}, bbox={box}, score={score}")
        if pose is not None and not all(math.isfinite(x) for x in pose if x is not None):
            raise _Skip("nan", f"non-finite number in the inline pose {pose}")
        if box[0] > box[2] or box[1] > box[3]:
            raise _Skip("malformed", f"box {box} has u_min > u_max or v_min > v_max")
        cls, sensor = rec["class"], rec["sensor"]
        if cls not in CLASSES:
            raise _Skip("unknown_class", f"class {cls!r} is not one of {', '.join(CLASSES)}")
        if self.sensors is not None:
            if sensor not in self.sensors:
                raise _Skip("unknown_sensor", f"sensor {sensor!r} is not known")
            w, h = self.sensors[sensor]
            lo = -0.5 - self.tol
            if (
                box[0] < lo
                or box[1] < lo
                or box[2] > w - 0.5 + self.tol
                or box[3] > h - 0.5 + self.tol
            ):
                raise _Skip("outside_image", f"box {box} outside the {w}x{h} image of {sensor}")
        last = self.last_t.get(sensor)
        if last is not None and t < last:
            raise _Skip("time_backwards", f"t={t} s is before {last} s for sensor {sensor}")
        if pose is not None:
            try:
                sample = PoseSample(t, pose[0], pose[1], pose[2])
            except PoseError as err:
                raise _Skip("malformed", f"inline pose: {err}") from None
            self.poses.setdefault(sensor, []).append(sample)
        self.last_t[sensor] = t
        # checked above as the constructor would (the record's numbers are floats already)
        return Detection._trusted(t, sensor, tuple(box), cls, score, rec["local_id"])  # type: ignore[arg-type]

    def time_of(self, value: Any, name: str) -> float:
        """A record's time (UNIX seconds): an ISO string, or a number after the epoch."""
        return _time_of(value, name, self.epoch_s)

    def result(self) -> tuple[list[Detection], IngestReport]:
        relative = (
            self.epoch_s is None
            and bool(self.accepted)
            and all(d.t_s < RELATIVE_BEFORE_S for d in self.accepted)
        )
        report = IngestReport(
            self.n_records,
            len(self.accepted),
            dict(self.counts),
            tuple(sorted(self.examples, key=lambda e: e.line)),
            self.epoch_s,
            relative,
            {k: tuple(v) for k, v in self.poses.items()},
        )
        return self.accepted, report


def _time_of(value: Any, name: str, epoch_s: float | None) -> float:
    """A record's time (UNIX seconds): an ISO string, or a number (after ``epoch_s``)."""
    if isinstance(value, str) and value.strip() and not _numeric(value):
        try:
            return parse_iso_time(value, name)
        except TimeFormatError as err:
            raise _Skip("malformed", str(err)) from None
    t = _float(value, name)
    return t if epoch_s is None else epoch_s + t


def _inline_pose(get: Callable[[str], Any]) -> tuple[float, float, float | None] | None:
    """``(pan, tilt, hfov or None)`` of a record's inline pose fields, None without one.

    ``get(name)`` is the field's value, None when absent or empty.
    """
    pan, tilt, hfov = (get(k) for k in POSE_FIELDS)
    if pan is None and tilt is None and hfov is None:
        return None
    if pan is None or tilt is None:
        raise _Skip("malformed", "an inline pose needs both pan_deg and tilt_deg")
    return (
        _float(pan, "pan_deg"),
        _float(tilt, "tilt_deg"),
        None if hfov is None else _float(hfov, "hfov_deg"),
    )


@contextmanager
def _open(source: Source, mode: str) -> Iterator[IO[str]]:
    if isinstance(source, str | os.PathLike):
        enc = "utf-8-sig" if "r" in mode else "utf-8"
        try:
            with open(source, mode, encoding=enc, newline="") as fh:
                yield fh
        except OSError as err:
            raise InputFileError(f"cannot open {os.fspath(source)}: {err.strerror}") from err
    else:
        yield source


def _shown(value: Any) -> str:
    """``value`` for a message: short, whatever its size (a 400-digit integer, a long text)."""
    if isinstance(value, int) and not isinstance(value, bool):
        digits = len(str(abs(value))) if abs(value) < 10**4000 else 4000
        if digits > 20:
            return f"an integer of {'over ' if digits >= 4000 else ''}{digits} digits"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _epoch(text: str, where: str) -> float:
    """The declared epoch (UNIX seconds) from its ISO text, or a one-line file error."""
    try:
        return parse_iso_time(text, "epoch")
    except TimeFormatError as err:
        raise InputFileError(f"{where}: {err}") from None


def _float(value: Any, name: str) -> float:
    if isinstance(value, bool) or value is None:
        raise _Skip("malformed", f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except OverflowError:  # an integer beyond a float's range (over 308 digits)
        raise _Skip(
            "malformed", f"{name} must be a number a float can hold, got {_shown(value)}"
        ) from None
    except (TypeError, ValueError):
        raise _Skip("malformed", f"{name} must be a number, got {_shown(value)}") from None


def read_detections_csv(
    source: Source,
    *,
    sensors: Mapping[str, tuple[int, int]] | None = None,
    max_examples: int = 5,
    edge_tolerance_px: float = 1.0,
) -> tuple[list[Detection], IngestReport]:
    """Read a detection CSV file (format in the module docstring).

    Parameters
    ----------
    source : path or text file
        The CSV.
    sensors : mapping of str to (width_px, height_px), optional
        Known sensors and image sizes; when given, records of other sensors and boxes
        outside the image are skipped.
    max_examples : int
        Skipped records kept as examples, per reason.
    edge_tolerance_px : float
        How far a box may reach past the image border (detectors that use pixel-edge
        coordinates report ``u_max = W``).

    Returns
    -------
    detections : list of Detection
        Accepted records in file order.
    report : IngestReport
        Counts and examples of skipped records.

    Raises
    ------
    InputFileError
        If the file cannot be read or lacks a required column.
    """
    col = _Collector(sensors, max_examples, edge_tolerance_px)
    with _open(source, "r") as fh:
        # Comment lines before the header: ``# epoch: <ISO 8601>`` declares the epoch.
        n_before = 0
        first = fh.readline()
        while first.lstrip().startswith("#"):
            n_before += 1
            key, sep, value = first.lstrip()[1:].partition(":")
            if sep and key.strip().lower() == "epoch":
                col.epoch_s = _epoch(value.strip(), f"detection CSV line {n_before}")
            first = fh.readline()
        if not first:
            raise InputFileError("detection CSV is empty (no header row)")
        reader = csv.reader(itertools.chain([first], fh))
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise InputFileError("detection CSV is empty (no header row)") from None
        except csv.Error as err:
            raise InputFileError(f"detection CSV header unreadable: {err}") from err
        required = [c for c in CSV_COLUMNS[:7] if c != "t"]
        missing = [c for c in required if c not in header]
        if "t" not in header and "time" not in header:
            missing.insert(0, "t (or time)")
        if missing:
            raise InputFileError(
                f"detection CSV lacks column(s) {', '.join(missing)}; header is {','.join(header)}"
            )
        if "t" in header and "time" in header:
            raise InputFileError("detection CSV has both a t and a time column: keep one")
        pos = {
            name: header.index(name)
            for name in (*CSV_COLUMNS, *POSE_FIELDS, "time")
            if name in header
        }
        for line, row in _csv_rows(reader, len(header), n_before, col):
            col.offer(line, functools.partial(_csv_record, row, pos, col))
    return col.result()


def _csv_record(row: list[str], pos: Mapping[str, int], col: _Collector) -> dict[str, Any]:
    def cell(name: str) -> str:
        return row[pos[name]].strip() if name in pos else ""

    sensor = cell("sensor")
    if not sensor:
        raise _Skip("malformed", "empty sensor")
    score = cell("score")
    local_id = cell("local_id")
    t_name = "t" if "t" in pos else "time"
    return {
        "t": col.time_of(cell(t_name), t_name),
        "sensor": sensor,
        "bbox": [_float(cell(c), c) for c in ("u_min", "v_min", "u_max", "v_max")],
        "class": cell("class"),
        "score": _float(score, "score") if score else None,
        "local_id": local_id or None,
        "pose": _inline_pose(lambda k: cell(k) or None),
    }


def read_detections_jsonl(
    source: Source,
    *,
    sensors: Mapping[str, tuple[int, int]] | None = None,
    max_examples: int = 5,
    edge_tolerance_px: float = 1.0,
) -> tuple[list[Detection], IngestReport]:
    """Read a detection JSON Lines file (format in the module docstring).

    Parameters and returns are those of :func:`read_detections_csv`.
    """
    col = _Collector(sensors, max_examples, edge_tolerance_px)
    with _open(source, "r") as fh:
        for line_no, text in _jsonl_lines(fh, col, "detection"):
            col.offer(line_no, functools.partial(_json_record, text, col))
    return col.result()


def _epoch_record(text: str) -> str | None:
    """The epoch text of a header record ``{"epoch": "..."}``; None for any other line."""
    try:
        obj = json.loads(text)
    except json.JSONDecodeError:
        return None
    if isinstance(obj, dict) and set(obj) == {"epoch"}:
        value = obj["epoch"]
        return value if isinstance(value, str) else repr(value)
    return None


def read_detection_records(
    records: Iterable[Any],
    *,
    sensors: Mapping[str, tuple[int, int]] | None = None,
    max_examples: int = 5,
    edge_tolerance_px: float = 1.0,
    epoch_s: float | None = None,
) -> tuple[list[Detection], IngestReport]:
    """Check already parsed JSON records (dicts) with the JSON Lines rules.

    The same answer as :func:`read_detections_jsonl` on the records written one per line
    (an issue's ``line`` is the record's 1-based position), without the text round trip.
    ``epoch_s`` (UNIX seconds) is the epoch of numeric ``t`` (a relative batch); None:
    numeric ``t`` are UNIX seconds.
    """
    col = _Collector(sensors, max_examples, edge_tolerance_px, epoch_s)
    for line_no, obj in enumerate(records, start=1):
        col.offer(line_no, functools.partial(_object_record, obj, col))
    return col.result()


def _json_record(text: str, col: _Collector) -> dict[str, Any]:
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as err:
        raise _Skip("malformed", f"invalid JSON: {err.msg} at column {err.colno}") from None
    return _object_record(obj, col)


def _object_record(obj: Any, col: _Collector) -> dict[str, Any]:
    if not isinstance(obj, dict):
        raise _Skip("malformed", f"a record must be a JSON object, got {type(obj).__name__}")
    if "t" in obj and "time" in obj:
        raise _Skip("malformed", "give t or time, not both")
    t_name = "time" if "time" in obj else "t"
    for key in (t_name, "sensor", "bbox", "class"):
        if key not in obj:
            raise _Skip("malformed", f"missing field {key!r}")
    t_value = obj[t_name]
    if t_name == "time" and not isinstance(t_value, str):
        raise _Skip("malformed", f"time must be an ISO 8601 string, got {_shown(t_value)}")
    sensor, cls, box = obj["sensor"], obj["class"], obj["bbox"]
    if not isinstance(sensor, str) or not sensor:
        raise _Skip("malformed", f"sensor must be a non-empty string, got {sensor!r}")
    if not isinstance(cls, str):
        raise _Skip("malformed", f"class must be a string, got {cls!r}")
    if not isinstance(box, list | tuple) or len(box) != 4:
        raise _Skip("malformed", f"bbox must be a list of 4 numbers, got {box!r}")
    local_id = obj.get("local_id")
    if local_id is not None:
        if isinstance(local_id, bool) or not isinstance(local_id, str | int):
            raise _Skip("malformed", f"local_id must be a string or integer, got {local_id!r}")
        local_id = str(local_id)
    score = obj.get("score")
    return {
        "t": col.time_of(t_value, t_name),
        "sensor": sensor,
        "bbox": [_float(b, "bbox") for b in box],
        "class": cls,
        "score": None if score is None else _float(score, "score"),
        "local_id": local_id,
        "pose": _inline_pose(obj.get),
    }


def read_detections(
    path: str | os.PathLike[str],
    *,
    sensors: Mapping[str, tuple[int, int]] | None = None,
    max_examples: int = 5,
    edge_tolerance_px: float = 1.0,
) -> tuple[list[Detection], IngestReport]:
    """Read ``.csv`` or ``.jsonl`` / ``.ndjson`` detections, by file suffix."""
    suffix = Path(path).suffix.lower()
    kwargs = {
        "sensors": sensors,
        "max_examples": max_examples,
        "edge_tolerance_px": edge_tolerance_px,
    }
    if suffix == ".csv":
        return read_detections_csv(path, **kwargs)  # type: ignore[arg-type]
    if suffix in (".jsonl", ".ndjson"):
        return read_detections_jsonl(path, **kwargs)  # type: ignore[arg-type]
    raise InputFileError(f"unknown detection file type {suffix!r} (use .csv or .jsonl)")


def write_detections_csv(dest: Source, detections: Iterable[Detection]) -> None:
    """Write detections as CSV (all columns of :data:`CSV_COLUMNS`)."""
    with _open(dest, "w") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(CSV_COLUMNS)
        for d in detections:
            writer.writerow(
                [
                    repr(d.t_s),
                    d.sensor,
                    *(repr(b) for b in d.bbox),
                    d.cls,
                    "" if d.score is None else repr(d.score),
                    "" if d.local_id is None else d.local_id,
                ]
            )


def write_detections_jsonl(dest: Source, detections: Iterable[Detection]) -> None:
    """Write detections as JSON Lines."""
    with _open(dest, "w") as fh:
        buf = io.StringIO()
        for d in detections:
            rec: dict[str, Any] = {
                "t": d.t_s,
                "sensor": d.sensor,
                "bbox": list(d.bbox),
                "class": d.cls,
            }
            if d.score is not None:
                rec["score"] = d.score
            if d.local_id is not None:
                rec["local_id"] = d.local_id
            buf.write(json.dumps(rec, allow_nan=False) + "\n")
        fh.write(buf.getvalue())


def _csv_rows(
    reader: Any, n_fields: int, n_before: int, col: Any
) -> Iterator[tuple[int, list[str]]]:
    """The data rows of a CSV after its header, each with its file line number.

    Unparsable rows and rows with the wrong number of fields are counted on ``col`` (any
    collector with ``n_records`` and ``skip(line, reason, message)``) as ``malformed``;
    blank rows are passed over. ``n_before`` is the number of lines before the reader's
    first (comment lines already consumed).
    """
    while True:
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as err:
            col.n_records += 1
            col.skip(reader.line_num + n_before, "malformed", f"unparsable CSV: {err}")
            continue
        if not row or all(not c.strip() for c in row):
            continue
        line = reader.line_num + n_before
        if len(row) != n_fields:
            col.n_records += 1
            col.skip(line, "malformed", f"{len(row)} fields, header has {n_fields}")
            continue
        yield line, row


def _jsonl_lines(fh: Iterable[str], col: Any, what: str) -> Iterator[tuple[int, str]]:
    """The record lines of a JSON Lines file, each with its line number.

    Blank lines are passed over; a first record ``{"epoch": "..."}`` sets ``col.epoch_s``
    (``what`` names the file kind in its error) and is not a record.
    """
    first = True
    for line_no, text in enumerate(fh, start=1):
        if not text.strip():
            continue
        if first:
            first = False
            epoch = _epoch_record(text)
            if epoch is not None:
                col.epoch_s = _epoch(epoch, f"{what} JSON Lines line {line_no}")
                continue
        yield line_no, text
