"""Pose records as posted -> pose samples; the inline poses of detection records.

A pose record (``POST /api/sensors/{id}/poses``) is ``{"t": UNIX s, or "time": ISO 8601
with a zone, "pan_deg", "tilt_deg", "hfov_deg"?, "roll_deg"?, "e_m", "n_m", "u_m"?,
"yaw_deg", "pitch_deg", "platform_roll_deg"?}``: the head's pan and tilt (degrees,
clockwise from the mount's zero / up from level), the lens's horizontal field of view
(degrees; the head's calibrated one when absent) and, for a moving platform, its position
(site-frame ENU metres; ``u_m`` defaults to the surveyed height) and attitude (degrees).
A record that is not one gives ``(index, reason, message)`` instead of a sample, for
:meth:`~.pose_book.PoseBook.check` to count.

A detection record may carry ``pan_deg``, ``tilt_deg`` and ``hfov_deg``: the pose of its
sensor at the detection's time (:func:`inline_poses`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from demtrack.core.camera.pose_series import PoseSample
from demtrack.core.errors import DemtrackError
from demtrack.core.io.times import parse_iso_time

__all__ = ["RecordIssue", "inline_poses", "parse_pose_records", "record_time"]

#: ``(index, reason, message)``: a record that gave no sample.
RecordIssue = tuple[int, str, str]


def _number(r: Mapping[str, Any], key: str) -> float | None:
    v = r.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise TypeError(f"{key} must be a number")
    return float(v)


def record_time(r: Mapping[str, Any]) -> float:
    """UNIX seconds of a record's ``t`` (number or ISO 8601 with a zone) or ``time``."""
    t = r.get("t", r.get("time"))
    if isinstance(t, str):
        return parse_iso_time(t, "t" if "t" in r else "time")
    if isinstance(t, bool) or not isinstance(t, int | float):
        raise TypeError("t must be UNIX seconds or an ISO 8601 time with a zone")
    return float(t)


def _sample(r: Any, head_u_m: float) -> PoseSample:
    if not isinstance(r, Mapping):
        raise TypeError("a pose record must be an object")
    t = record_time(r)
    pan, tilt = _number(r, "pan_deg"), _number(r, "tilt_deg")
    if pan is None or tilt is None:
        raise TypeError("pan_deg and tilt_deg are required")
    e, n, u = _number(r, "e_m"), _number(r, "n_m"), _number(r, "u_m")
    position = None
    if e is not None or n is not None:
        if e is None or n is None:
            raise TypeError("a position needs both e_m and n_m")
        position = (e, n, head_u_m if u is None else u)
    yaw, pitch, proll = (_number(r, k) for k in ("yaw_deg", "pitch_deg", "platform_roll_deg"))
    attitude = None
    if yaw is not None or pitch is not None:
        if yaw is None or pitch is None:
            raise TypeError("a platform attitude needs both yaw_deg and pitch_deg")
        attitude = (yaw, pitch, 0.0 if proll is None else proll)
    roll = _number(r, "roll_deg")
    return PoseSample(
        t,
        pan,
        tilt,
        hfov_deg=_number(r, "hfov_deg"),
        roll_deg=0.0 if roll is None else roll,
        position_enu=position,
        platform_ypr_deg=attitude,
    )


def _is_finite_record(r: Any) -> bool:
    if not isinstance(r, Mapping):
        return True
    return all(
        not isinstance(v, float) or math.isfinite(v) for v in r.values() if not isinstance(v, bool)
    )


def parse_pose_records(
    records: Sequence[Any], head_u_m: float = 0.0
) -> list[PoseSample | RecordIssue]:
    """Each record's sample, or its issue (``not_finite``, ``bad_pose``), in order."""
    out: list[PoseSample | RecordIssue] = []
    for i, r in enumerate(records):
        if not _is_finite_record(r):
            out.append((i, "not_finite", "pose holds NaN or infinity"))
            continue
        try:
            out.append(_sample(r, head_u_m))
        except (TypeError, ValueError, DemtrackError) as exc:
            out.append((i, "bad_pose", str(exc).splitlines()[0] if str(exc) else "not a pose"))
    return out


def inline_poses(
    records: Sequence[Any], sensors: Mapping[str, Any]
) -> dict[str, list[PoseSample | RecordIssue]]:
    """The inline poses of detection records, per sensor, in record order.

    Only records of a known sensor with ``pan_deg`` and ``tilt_deg`` count; the rest of
    a detection record is the detection reader's to check.
    """
    out: dict[str, list[PoseSample | RecordIssue]] = {}
    for i, r in enumerate(records):
        if not isinstance(r, Mapping) or "pan_deg" not in r or "tilt_deg" not in r:
            continue
        sensor = r.get("sensor")
        if not isinstance(sensor, str) or sensor not in sensors:
            continue
        fields = {k: r[k] for k in ("pan_deg", "tilt_deg", "hfov_deg") if k in r}
        if "t" in r:
            fields["t"] = r["t"]
        elif "time" in r:
            fields["time"] = r["time"]
        (one,) = parse_pose_records([fields])
        out.setdefault(sensor, []).append(one if not isinstance(one, tuple) else (i, *one[1:]))
    return out
