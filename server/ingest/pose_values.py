"""Pose records as posted -> checked pose samples (the pose file reader's rules).

A pose record (``POST /api/sensors/{id}/poses``) is ``{"t": UNIX s, or "time": ISO 8601
with a zone, "pan_deg", "tilt_deg", "hfov_deg"?, "roll_deg"?, "e_m", "n_m", "u_m"?,
"yaw_deg", "pitch_deg", "platform_roll_deg"?}``: a record of the pose JSON Lines format
(:mod:`demtrack.core.io.pose_io`) without its ``sensor``, which the path names. The
reader checks each one (``malformed``, ``nan``, ``out_of_range``, order within the
batch); ``u_m`` defaults to the sensor's surveyed height. What the reader accepts then
meets the cross-batch checks of :meth:`~.pose_book.PoseBook.check`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from demtrack.core.camera.pose_series import PoseSample
from demtrack.core.io.pose_io import read_pose_records

from .validate import MAX_ISSUES

__all__ = ["ParsedPoses", "parse_pose_records"]


@dataclass
class ParsedPoses:
    """One batch's samples of one sensor and what its reader skipped.

    Attributes
    ----------
    samples : list of PoseSample
        Accepted by the reader, in record order.
    counts : dict of str to int
        Skipped records per reason (non-zero ones).
    issues : list of dict
        The first skipped records: ``index`` (0-based), ``reason``, ``message``.
    n_records : int
        Records in the batch.
    """

    samples: list[PoseSample]
    counts: dict[str, int] = field(default_factory=dict)
    issues: list[dict[str, Any]] = field(default_factory=list)
    n_records: int = 0

    @classmethod
    def of(cls, samples: Sequence[PoseSample]) -> ParsedPoses:
        """Samples handed over as values (a head adapter's): nothing skipped yet."""
        return cls(list(samples), n_records=len(samples))


def _with_sensor(r: Any, sensor: str, head_u_m: float) -> Any:
    if not isinstance(r, Mapping):
        return r
    out = {**r, "sensor": sensor}
    if "e_m" in out and "n_m" in out and out.get("u_m") is None:
        out["u_m"] = head_u_m
    return out


def parse_pose_records(
    records: Sequence[Any], sensor: str, head_u_m: float = 0.0, epoch_s: float | None = None
) -> ParsedPoses:
    """Check posted pose records of ``sensor`` with the pose file reader.

    ``head_u_m``: the height (site frame, m) a position without ``u_m`` gets; ``epoch_s``
    (UNIX s): the epoch of numeric ``t`` (None: UNIX seconds).
    """
    series, report = read_pose_records(
        [_with_sensor(r, sensor, head_u_m) for r in records],
        max_examples=MAX_ISSUES,
        epoch_s=epoch_s,
    )
    got = series.get(sensor)
    issues = [
        {"index": e.line - 1, "reason": e.reason, "message": e.message}
        for e in report.examples[:MAX_ISSUES]
    ]
    return ParsedPoses(
        [] if got is None else got.samples(),
        {k: v for k, v in report.counts.items() if v},
        issues,
        report.n_records,
    )
