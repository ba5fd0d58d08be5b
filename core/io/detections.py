"""Detection files: reading CSV and JSON Lines with a report of what was skipped.

Two formats hold the same records, one detection per record. Times are seconds (``t``,
float, any origin common to all sensors); boxes are pixels in demtrack's convention
(``(0, 0)`` is the centre of the top-left pixel, so an image of width ``W`` spans
``u in [-0.5, W - 0.5]``).

CSV (UTF-8, comma-separated, a header row naming the columns, in any order; extra columns
are ignored)::

    t,sensor,u_min,v_min,u_max,v_max,class,score,local_id
    12.40,cam0,311.0,208.5,352.0,290.0,human,0.91,17
    12.40,cam1,80,40,160,95,vehicle,,

``score`` and ``local_id`` are optional columns, and an empty cell means "none".

JSON Lines (UTF-8, one JSON object per line; blank lines are ignored)::

    {"t": 12.4, "sensor": "cam0", "bbox": [311.0, 208.5, 352.0, 290.0], "class": "human",
     "score": 0.91, "local_id": "17"}

(one line in the file); ``score`` and ``local_id`` may be absent or null; a numeric
``local_id`` is kept as its decimal string.

``class`` is ``vehicle`` or ``human``. Every record is either returned or counted under
exactly one reason, checked in this order:

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
import json
import math
import os
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from ..errors import InputFileError
from ..tracking.types import CLASSES, Detection

__all__ = [
    "CSV_COLUMNS",
    "REASONS",
    "IngestIssue",
    "IngestReport",
    "read_detection_records",
    "read_detections",
    "read_detections_csv",
    "read_detections_jsonl",
    "write_detections_csv",
    "write_detections_jsonl",
]

#: CSV columns; the first seven are required.
CSV_COLUMNS = ("t", "sensor", "u_min", "v_min", "u_max", "v_max", "class", "score", "local_id")
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
    """

    n_records: int
    n_accepted: int
    counts: dict[str, int] = field(default_factory=dict)
    examples: tuple[IngestIssue, ...] = ()

    @property
    def n_skipped(self) -> int:
        """Records skipped (``n_records - n_accepted``)."""
        return sum(self.counts.values())

    def summary(self) -> str:
        """One line: accepted count and non-zero skip counts."""
        parts = [f"{k}={v}" for k, v in self.counts.items() if v]
        tail = f", skipped {self.n_skipped} ({', '.join(parts)})" if parts else ""
        return f"{self.n_accepted} of {self.n_records} detections accepted{tail}"


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
    ) -> None:
        self.sensors = sensors
        self.max_examples = max_examples
        self.tol = edge_tolerance_px
        self.counts = dict.fromkeys(REASONS, 0)
        self.examples: list[IngestIssue] = []
        self.accepted: list[Detection] = []
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
        numbers = [t, *box] + ([score] if score is not None else [])
        if not all(math.isfinite(x) for x in numbers):
            raise _Skip("nan", f"non-finite number in t={t}, bbox={box}, score={score}")
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
        self.last_t[sensor] = t
        # checked above as the constructor would (the record's numbers are floats already)
        return Detection._trusted(t, sensor, tuple(box), cls, score, rec["local_id"])  # type: ignore[arg-type]

    def result(self) -> tuple[list[Detection], IngestReport]:
        report = IngestReport(
            self.n_records,
            len(self.accepted),
            dict(self.counts),
            tuple(sorted(self.examples, key=lambda e: e.line)),
        )
        return self.accepted, report


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
        reader = csv.reader(fh)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise InputFileError("detection CSV is empty (no header row)") from None
        except csv.Error as err:
            raise InputFileError(f"detection CSV header unreadable: {err}") from err
        missing = [c for c in CSV_COLUMNS[:7] if c not in header]
        if missing:
            raise InputFileError(
                f"detection CSV lacks column(s) {', '.join(missing)}; header is {','.join(header)}"
            )
        pos = {name: header.index(name) for name in CSV_COLUMNS if name in header}
        while True:
            try:
                row = next(reader)
            except StopIteration:
                break
            except csv.Error as err:
                col.n_records += 1
                col.skip(reader.line_num, "malformed", f"unparsable CSV: {err}")
                continue
            if not row or all(not c.strip() for c in row):
                continue
            line = reader.line_num
            if len(row) != len(header):
                col.n_records += 1
                col.skip(line, "malformed", f"{len(row)} fields, header has {len(header)}")
                continue
            col.offer(line, functools.partial(_csv_record, row, pos))
    return col.result()


def _csv_record(row: list[str], pos: Mapping[str, int]) -> dict[str, Any]:
    def cell(name: str) -> str:
        return row[pos[name]].strip() if name in pos else ""

    sensor = cell("sensor")
    if not sensor:
        raise _Skip("malformed", "empty sensor")
    score = cell("score")
    local_id = cell("local_id")
    return {
        "t": _float(cell("t"), "t"),
        "sensor": sensor,
        "bbox": [_float(cell(c), c) for c in ("u_min", "v_min", "u_max", "v_max")],
        "class": cell("class"),
        "score": _float(score, "score") if score else None,
        "local_id": local_id or None,
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
        for line_no, text in enumerate(fh, start=1):
            if text.strip():
                col.offer(line_no, functools.partial(_json_record, text))
    return col.result()


def read_detection_records(
    records: Iterable[Any],
    *,
    sensors: Mapping[str, tuple[int, int]] | None = None,
    max_examples: int = 5,
    edge_tolerance_px: float = 1.0,
) -> tuple[list[Detection], IngestReport]:
    """Check already parsed JSON records (dicts) with the JSON Lines rules.

    The same answer as :func:`read_detections_jsonl` on the records written one per line
    (an issue's ``line`` is the record's 1-based position), without the text round trip.
    """
    col = _Collector(sensors, max_examples, edge_tolerance_px)
    for line_no, obj in enumerate(records, start=1):
        col.offer(line_no, functools.partial(_object_record, obj))
    return col.result()


def _json_record(text: str) -> dict[str, Any]:
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as err:
        raise _Skip("malformed", f"invalid JSON: {err.msg} at column {err.colno}") from None
    return _object_record(obj)


def _object_record(obj: Any) -> dict[str, Any]:
    if not isinstance(obj, dict):
        raise _Skip("malformed", f"a record must be a JSON object, got {type(obj).__name__}")
    for key in ("t", "sensor", "bbox", "class"):
        if key not in obj:
            raise _Skip("malformed", f"missing field {key!r}")
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
        "t": _float(obj["t"], "t"),
        "sensor": sensor,
        "bbox": [_float(b, "bbox") for b in box],
        "class": cls,
        "score": None if score is None else _float(score, "score"),
        "local_id": local_id,
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
