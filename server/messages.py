"""WebSocket messages: pydantic models with a ``type`` discriminator.

Server -> client stream messages (``fix``, ``track_update``, ``sensor_status``,
``sensor_pose``, ``event``, ``marker``) carry ``seq``, a number that grows by one per
stored message; a client that reconnects with ``/ws?since=N&store=<store_id>`` (or
sends ``{"type": "resume", "since": N}``) is sent every stream message with ``seq > N``
first; a ``since`` of another store (``hello.store_id``) or beyond the newest message
starts the client over (``hello.start_over``). Control messages (``hello``, ``pong``,
``error``) are not stored and have ``seq: null``. A client that connects with
``/ws?batch=1`` may also be sent ``batch`` messages (``seq: null``): several stream
messages in one frame, in ``seq`` order, each as it would have come alone.

Client -> server: ``ping`` and ``resume``. Anything else gets an ``error`` message and the
connection stays up.

The JSON schema of every message is exported to ``web/schema/messages.json``
(``python -m demtrack.server.messages``); a test fails when that copy is stale.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

__all__ = [
    "AnyMessage",
    "BATCH_MAX_MESSAGES",
    "BatchMessage",
    "ClientMessage",
    "ErrorMessage",
    "EventBody",
    "EventMessage",
    "FixBody",
    "FixMessage",
    "HelloMessage",
    "HitBody",
    "MAX_SEQ",
    "MarkerBody",
    "MarkerMessage",
    "PingMessage",
    "PongMessage",
    "ResumeMessage",
    "SCHEMA_PATH",
    "SensorPoseMessage",
    "SensorStatusMessage",
    "ServerMessage",
    "StreamMessage",
    "TrackBody",
    "TrackPointBody",
    "TrackUpdateMessage",
    "client_adapter",
    "messages_schema",
    "schema_text",
    "write_schema",
]

#: Where the exported schema lives, relative to the repository root.
SCHEMA_PATH = Path("web") / "schema" / "messages.json"
#: The most stream messages one ``batch`` message carries.
BATCH_MAX_MESSAGES = 256


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class HitBody(_Model):
    """One point where a viewing ray meets the ground.

    ``e_m, n_m, u_m``: site frame (m). ``h_m``: above the WGS84 ellipsoid.
    """

    e_m: float
    n_m: float
    u_m: float
    lat_deg: float
    lon_deg: float
    h_m: float
    sigma_m: float = Field(description="1-sigma horizontal uncertainty (m)")
    cov_en_m2: list[list[float]] | None = Field(
        default=None,
        min_length=2,
        max_length=2,
        description="Horizontal covariance [[ee, en], [ne, nn]] (m^2): elongated along the"
        " ray on flat ground; terrain hits only (the tracker's measurement noise)",
    )


class FixBody(_Model):
    """A detection's viewing ray (bottom-centre of its box) and every terrain hit."""

    detection_id: int
    t_s: float
    sensor: str
    cls: Literal["vehicle", "human"]
    score: float | None
    bbox: tuple[float, float, float, float]
    foot_pixel: tuple[float, float]
    origin_enu: tuple[float, float, float]
    direction_enu: tuple[float, float, float]
    hits: list[HitBody] = Field(description="every terrain crossing, nearest first")
    road_hit: HitBody | None = None
    tracked: bool = Field(description="false when the tracker refused it (arrived too late)")


class TrackPointBody(_Model):
    """One estimate of a track."""

    t_s: float
    e_m: float
    n_m: float
    u_m: float
    lat_deg: float
    lon_deg: float
    h_m: float
    sensors: list[str]
    detection_ids: list[int] = Field(description="the detections (fixes) behind this point")
    time_utc: str | None = Field(
        default=None, description="t_s as ISO 8601 UTC with Z (HTTP answers; not streamed)"
    )


class TrackBody(_Model):
    """A confirmed track, or its revised tail.

    In a ``track_update`` message ``points`` holds the points from ``first_index`` on
    (the newest ones may be revised by smoothing); a client replaces its copy from that
    index. From ``GET /api/tracks`` it holds every point in the requested window.
    """

    id: int
    cls: Literal["vehicle", "human"]
    sensors: list[str]
    gaps: list[tuple[float, float]]
    live: bool
    n_points: int
    first_index: int
    points: list[TrackPointBody]


class FixMessage(_Model):
    """A new fix with all its ray hits."""

    type: Literal["fix"] = "fix"
    seq: int
    fix: FixBody


class TrackUpdateMessage(_Model):
    """A track was confirmed, grew, was revised or ended."""

    type: Literal["track_update"] = "track_update"
    seq: int
    track: TrackBody


class SensorStatusMessage(_Model):
    """Per-sensor ingest state after a batch."""

    type: Literal["sensor_status"] = "sensor_status"
    seq: int
    sensor: str
    last_t_s: float | None
    n_detections: int


class SensorPoseMessage(_Model):
    """A sensor's newest pose telemetry and its ground footprint at that pose.

    Sent after the batch that stored it, at most once per ``pose_message_interval_s``
    (0.2 s) per sensor (always the newest pose: one held back by the rate limit goes out
    when the interval ends).
    Angles in degrees: ``pan_deg`` clockwise from the mount's zero, ``tilt_deg`` up from
    level, ``roll_deg`` about the optical axis, ``hfov_deg`` the horizontal field of view
    (null: the calibrated lens). ``footprint``: as ``GET /api/sensors``'s (``enu``
    border points, ``lonlat`` GeoJSON Polygon, ``complete``, ``n_rays``, ``n_missed``).
    """

    type: Literal["sensor_pose"] = "sensor_pose"
    seq: int
    sensor: str
    t_s: float = Field(description="the pose's time (UNIX s, UTC)")
    pan_deg: float
    tilt_deg: float
    roll_deg: float
    hfov_deg: float | None
    footprint: dict[str, Any] | None = Field(description="ground footprint at this pose")


class EventBody(_Model):
    """A detected event, as stored in the ``activity`` table and listed by ``/api/events``.

    ``kind``: ``loitering``, ``rendezvous``, ``convoy`` (episodes that last), ``zone-enter``,
    ``zone-leave`` (instants), ``handoff`` (a live track's predicted exit from its current
    sensor and the next sensor: ``t_end_s`` is the predicted exit time), ``track_confirmed``,
    ``track_ended``. An episode is streamed when it starts (``state: start``) and when it
    ends (``state: end``, final ``t_end_s``); the stored row follows it in between.
    """

    id: int | None = Field(default=None, description="row id in the activity table")
    key: str = Field(description="stable identity: kind, targets and start")
    identity: str = Field(description="kind and targets (episodes of one identity follow on)")
    kind: str
    state: Literal["start", "update", "end"]
    t_start_s: float
    t_end_s: float
    track_ids: list[int] = Field(description="targets involved (a convoy: leader first)")
    sensors: list[str] = Field(description="sensors that saw them (hand-off: current, next)")
    p_enu: tuple[float, float, float] = Field(description="where, site frame (m)")
    lat_deg: float
    lon_deg: float
    h_m: float = Field(description="above the WGS84 ellipsoid")
    details: dict[str, Any] = Field(description="kind-specific figures")
    open: bool = Field(description="an episode still going on")


class EventMessage(_Model):
    """A log line; ``kind``: ``ingest``, or a detected event's kind (then ``event``)."""

    type: Literal["event"] = "event"
    seq: int
    kind: str
    t_s: float | None
    text: str
    event: EventBody | None = Field(default=None, description="the detected event, if any")


class MarkerBody(_Model):
    """A point an operator keeps (``/api/markers``): where, when, and what it is."""

    id: int = Field(description="marker id (never reused)")
    t_s: float = Field(description="the moment it marks (UNIX s, UTC)")
    time_utc: str = Field(description="t_s as ISO 8601 UTC with Z")
    name: str
    note: str
    e_m: float = Field(description="site frame east (m)")
    n_m: float = Field(description="site frame north (m)")
    u_m: float = Field(description="site frame up (m)")
    lat_deg: float
    lon_deg: float
    h_m: float = Field(description="above the WGS84 ellipsoid (m)")
    mgrs: str = Field(description="MGRS grid reference, 1 m precision")
    utm: str | None = Field(
        default=None,
        description="UTM zone, band, easting and northing (17T 616941E 4468136N); null at"
        " the poles and for markers kept before it was recorded",
    )
    source: dict[str, Any] = Field(description="where it came from (sensor, pixel, rule)")


class MarkerMessage(_Model):
    """A marker kept (``action: add``), renamed or noted (``update``), or removed (``delete``).

    ``marker``: the marker as stored now (null for ``delete``).
    """

    type: Literal["marker"] = "marker"
    action: Literal["add", "update", "delete"]
    id: int
    marker: MarkerBody | None
    seq: int


StreamMessage = Annotated[
    FixMessage
    | TrackUpdateMessage
    | SensorStatusMessage
    | SensorPoseMessage
    | EventMessage
    | MarkerMessage,
    Field(discriminator="type"),
]


class BatchMessage(_Model):
    """Several stream messages in one frame (only to clients that asked: ``/ws?batch=1``).

    The server sends one whenever a client's queue (or a resume's replay) holds several
    messages, up to 256 of them or about 1 MB of text; a lone message still comes as
    itself. A client applies ``messages`` in order, exactly as if each had come alone.
    """

    type: Literal["batch"] = "batch"
    seq: None = None
    messages: list[StreamMessage] = Field(
        min_length=1,
        max_length=BATCH_MAX_MESSAGES,
        description="stream messages, in seq order",
    )


#: The largest ``since`` a client may ask for (SQLite's largest integer).
MAX_SEQ = 2**63 - 1


class HelloMessage(_Model):
    """First message on a connection (and the answer to a ``resume`` that cannot resume).

    ``store_id`` names the database the sequence numbers belong to (a new one after the
    server starts on a fresh file). ``start_over`` is true when the ``since`` asked for
    cannot be resumed from - it belongs to another store (``/ws?store=<id>`` differs) or
    lies beyond ``last_seq`` - so the client must drop what it holds and reload; it is
    then sent every message after ``last_seq``.
    """

    type: Literal["hello"] = "hello"
    seq: None = None
    last_seq: int = Field(description="the newest stored stream message")
    since: int | None = Field(description="the resume point asked for, if any")
    store_id: str = Field(description="the store (database) the sequence numbers belong to")
    start_over: bool = Field(
        default=False,
        description="since cannot be resumed (another store, or beyond last_seq): start over",
    )


class PongMessage(_Model):
    """Answer to ``ping``."""

    type: Literal["pong"] = "pong"
    seq: None = None
    nonce: str | int | None = None


class ErrorMessage(_Model):
    """A client message could not be handled; the connection stays up."""

    type: Literal["error"] = "error"
    seq: None = None
    message: str


class PingMessage(_Model):
    """Client -> server: answered with ``pong``."""

    type: Literal["ping"]
    nonce: str | int | None = None


class ResumeMessage(_Model):
    """Client -> server: send every stream message with ``seq > since``."""

    type: Literal["resume"]
    since: int = Field(ge=0, le=MAX_SEQ)


ServerMessage = Annotated[
    FixMessage
    | TrackUpdateMessage
    | SensorStatusMessage
    | SensorPoseMessage
    | EventMessage
    | MarkerMessage
    | BatchMessage
    | HelloMessage
    | PongMessage
    | ErrorMessage,
    Field(discriminator="type"),
]
ClientMessage = Annotated[PingMessage | ResumeMessage, Field(discriminator="type")]
AnyMessage = Annotated[
    FixMessage
    | TrackUpdateMessage
    | SensorStatusMessage
    | SensorPoseMessage
    | EventMessage
    | MarkerMessage
    | BatchMessage
    | HelloMessage
    | PongMessage
    | ErrorMessage
    | PingMessage
    | ResumeMessage,
    Field(discriminator="type"),
]

_SERVER_TYPES = [
    "fix",
    "track_update",
    "sensor_status",
    "sensor_pose",
    "event",
    "marker",
    "batch",
    "hello",
    "pong",
    "error",
]
_CLIENT_TYPES = ["ping", "resume"]


def client_adapter() -> TypeAdapter:
    """A validator for client messages."""
    return TypeAdapter(ClientMessage)


def messages_schema() -> dict:
    """The JSON schema of every message (one discriminated union)."""
    schema = TypeAdapter(AnyMessage).json_schema()
    schema["title"] = "demtrack WebSocket messages"
    schema["description"] = (__doc__ or "").strip().split("\n\n")[1].replace("\n", " ")
    schema["x-server-types"] = _SERVER_TYPES
    schema["x-client-types"] = _CLIENT_TYPES
    return schema


def schema_text() -> str:
    """The exported file's exact text."""
    return json.dumps(messages_schema(), indent=2, sort_keys=True) + "\n"


def write_schema(path: str | Path = SCHEMA_PATH) -> Path:
    """Write :func:`schema_text` to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(schema_text(), encoding="utf-8")
    return path


if __name__ == "__main__":
    sys.stdout.write(f"wrote {write_schema(sys.argv[1] if len(sys.argv) > 1 else SCHEMA_PATH)}\n")
