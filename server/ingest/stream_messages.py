"""The typed stream messages the pipeline stores and publishes (msgspec structs).

Each struct encodes, with the store's codec (:mod:`demtrack.server.store.codec`), to
exactly the JSON of the message the pydantic models of :mod:`demtrack.server.messages`
describe: its tag (``type``) first, then its fields in the order declared here, ``seq``
appended when published. The bodies they carry (fix, track, activity event) stay the
JSON-ready dicts the store keeps, so a fix body encoded for the fixes table is reused,
not encoded again. An ``ingest`` log line has no ``event`` key: a struct of its own.
"""

from __future__ import annotations

from typing import Any

import msgspec

__all__ = [
    "EventPayload",
    "FixPayload",
    "IngestPayload",
    "SensorPosePayload",
    "SensorStatusPayload",
    "StreamPayload",
    "TrackUpdatePayload",
]


class FixPayload(msgspec.Struct, tag_field="type", tag="fix", frozen=True):
    """``fix``: a new fix with all its ray hits (``fix``: the stored fix body)."""

    fix: dict[str, Any]


class TrackUpdatePayload(msgspec.Struct, tag_field="type", tag="track_update", frozen=True):
    """``track_update``: a track's body from ``first_index`` on."""

    track: dict[str, Any]


class SensorStatusPayload(msgspec.Struct, tag_field="type", tag="sensor_status", frozen=True):
    """``sensor_status``: a sensor's newest detection time (s) and its detection count."""

    sensor: str
    last_t_s: float | None
    n_detections: int


class SensorPosePayload(msgspec.Struct, tag_field="type", tag="sensor_pose", frozen=True):
    """``sensor_pose``: a sensor's newest pose (degrees, UNIX s) and its ground footprint."""

    sensor: str
    t_s: float
    pan_deg: float
    tilt_deg: float
    roll_deg: float
    hfov_deg: float | None
    footprint: dict[str, Any] | None


class EventPayload(msgspec.Struct, tag_field="type", tag="event", frozen=True):
    """``event`` of a detected event: its log line and its activity body (``event``)."""

    kind: str
    t_s: float | None
    text: str
    event: dict[str, Any]


class IngestPayload(msgspec.Struct, tag_field="type", tag="event", frozen=True):
    """``event`` of kind ``ingest``: one batch's log line (no activity body)."""

    kind: str
    t_s: float | None
    text: str


StreamPayload = (
    FixPayload
    | TrackUpdatePayload
    | SensorStatusPayload
    | SensorPosePayload
    | EventPayload
    | IngestPayload
)
