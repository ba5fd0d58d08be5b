"""The ``event`` stream messages: tracks confirmed and ended, activity, batches ingested.

An event message carries its log line (``text``, from :data:`EVENT_TEXT` by kind) and,
for a detected event, its activity body (``event``: the dict the ``activity`` table
stores). Kinds are :class:`~demtrack.core.activity.kinds.EventKind` values.
"""

from __future__ import annotations

from typing import Any

from demtrack.core.activity.kinds import EventKind
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.io.times import clock_utc
from demtrack.core.tracking.types import Track

from .stream_messages import EventPayload, IngestPayload

__all__ = ["EVENT_TEXT", "event_message", "ingest_message", "track_event"]

#: The log line of each kind (``str.format`` fields: ids, zone, current, next, exit, cls;
#: ``exit`` is a UTC clock time, ``14:32:05Z``).
EVENT_TEXT: dict[str, str] = {
    EventKind.LOITERING: "track {ids} loitering",
    EventKind.RENDEZVOUS: "tracks {ids} rendezvous",
    EventKind.CONVOY: "tracks {ids} in convoy",
    EventKind.ZONE_ENTER: "track {ids} entered {zone}",
    EventKind.ZONE_LEAVE: "track {ids} left {zone}",
    EventKind.HANDOFF: "track {ids}: {current} loses it at {exit}, next {next}",
    EventKind.TRACK_CONFIRMED: "track {ids} ({cls}) confirmed",
    EventKind.TRACK_ENDED: "track {ids} ({cls}) ended",
}


def event_message(body: dict[str, Any]) -> EventPayload:
    """The ``event`` stream message of an activity body."""
    d = body.get("details", {})
    text = EVENT_TEXT.get(body["kind"], body["kind"]).format(
        ids=", ".join(str(i) for i in body["track_ids"]),
        zone=d.get("zone", ""),
        current=d.get("current"),
        next=d.get("next_sensor"),
        exit=clock_utc(d["exit_t_s"]) if d.get("exit_t_s") is not None else "an unknown time",
        cls=d.get("cls", ""),
    )
    if body["state"] == "end":
        text += f" (ended, {body['t_end_s'] - body['t_start_s']:.0f} s)"
    return EventPayload(
        kind=body["kind"],
        t_s=body["t_end_s"] if body["state"] == "end" else body["t_start_s"],
        text=text,
        event=body,
    )


def track_event(kind: EventKind, track: Track, frame: LocalFrame) -> EventPayload:
    """The ``event`` message of ``track`` confirmed or ended (at its newest point)."""
    last = track.points[-1]
    t, where = last.t_s, last.p_enu
    lat, lon, h = (float(v) for v in frame.to_geodetic(*where))
    body = {
        "key": f"{kind}:{track.id}",
        "identity": f"{kind}:{track.id}",
        "kind": kind.value,
        "state": "start",
        "t_start_s": t,
        "t_end_s": t,
        "track_ids": [track.id],
        "sensors": sorted(track.sensors),
        "p_enu": [float(v) for v in where],
        "lat_deg": lat,
        "lon_deg": lon,
        "h_m": h,
        "details": {"cls": track.cls, "n_points": len(track.points)},
        "open": False,
    }
    return event_message(body)


def ingest_message(ack: dict[str, Any], n_fixes: int, t_s: float | None) -> IngestPayload:
    """The ``ingest`` log line of one acknowledged batch (``t_s``: its newest detection)."""
    text = (
        f"batch {ack['batch_id']}: {ack['accepted']} of {ack['n_records']} detections"
        f" accepted, {n_fixes} fixes"
    )
    return IngestPayload(kind=EventKind.INGEST.value, t_s=t_s, text=text)
