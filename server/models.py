"""Pydantic models at the HTTP boundary (requests and documented responses)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from demtrack.core.io.times import parse_iso_time

from .messages import TrackBody

__all__ = [
    "DetectionBatch",
    "FrameOut",
    "GeolocateBatchRequest",
    "GeolocateBatchResponse",
    "GeolocateRequest",
    "GeolocationOut",
    "GridOut",
    "HealthOut",
    "IngestAck",
    "IngestIssueOut",
    "SensorOut",
    "SiteOut",
    "StoredDetectionOut",
    "TracksOut",
]

Rule = Literal["first", "last", "all", "road"]
SensorId = Field(min_length=1, max_length=200, description="sensor id from site.json")


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class _Response(BaseModel):
    model_config = ConfigDict(extra="allow")


# ----------------------------------------------------------------------- site
class FrameOut(_Response):
    """The site frame's anchor (WGS84, ellipsoidal height)."""

    lat_deg: float
    lon_deg: float
    h_m: float
    crs: str


class GridOut(_Response):
    """A north-up grid in the site frame; ``bounds_enu`` are the outer cell edges (m)."""

    x_min: float
    y_max: float
    cell_m: float
    nrows: int
    ncols: int
    bounds_enu: tuple[float, float, float, float]


class SiteOut(_Response):
    """Site metadata."""

    name: str
    frame: FrameOut
    vertical_datum: str = Field(description="what local-frame Z (DEM elevations) is measured from")
    geoid_undulation_m: float = Field(
        description="N in h = H + N at the frame's anchor, from the site's vertical datum"
    )
    elevation_datum: str = Field(
        "WGS84 ellipsoid (no geoid model)",
        description="the datum of sea-level heights at this site (the readout's elevation_m, "
        "KML absolute, GPX ele): e.g. 'EGM96 geoid'",
    )
    heights: str
    crs_wkt: str | None = Field(description="WKT of the DEM grid's 2-D CRS, if known")
    dem: GridOut
    elevation_range_m: tuple[float, float]
    bounds_lonlat: tuple[float, float, float, float] = Field(
        description="lon_min, lat_min, lon_max, lat_max of the DEM's outer corners"
    )
    orthophoto: GridOut | None
    roads: int = Field(description="number of road centre lines")
    sensors: list[str]


class SensorOut(_Response):
    """A sensor at its current pan and tilt, with its ground footprint."""

    id: str
    name: str
    position_enu: tuple[float, float, float]
    lat_deg: float
    lon_deg: float
    h_m: float
    pan_deg: float
    tilt_deg: float
    width_px: int
    height_px: int
    intrinsics: dict[str, float]
    image: bool
    footprint: dict[str, Any]
    active: bool = Field(
        default=False,
        description="a PTZ head: its detections are geolocated with its pose telemetry",
    )
    telemetry: bool = Field(
        default=False, description="geolocated with pose telemetry (active, or it reported poses)"
    )
    pose: dict[str, Any] | None = Field(
        default=None,
        description="its newest reported pose (t_s, time_utc, pan/tilt/roll/hfov in degrees);"
        " null when it never reported one. pan_deg/tilt_deg and footprint are then that pose's",
    )


# ------------------------------------------------------------------ geolocate
class GeolocateRequest(_Request):
    """One pixel of one sensor; ``(0, 0)`` is the centre of the top-left pixel."""

    sensor: str = SensorId
    u: float = Field(description="column (px)")
    v: float = Field(description="row (px)")
    rule: Rule = "all"
    pixel_sigma_px: float = Field(default=1.0, gt=0, le=1000)


class GeolocateBatchRequest(_Request):
    """Several pixels of one sensor."""

    sensor: str = SensorId
    pixels: list[tuple[float, float]] = Field(min_length=1, max_length=10_000)
    rule: Rule = "all"
    pixel_sigma_px: float = Field(default=1.0, gt=0, le=1000)


class GeolocationOut(_Response):
    """Same content as ``demtrack geolocate --json``."""

    sensor: str
    pixel: tuple[float, float]
    rule: str
    status: str
    crossed_nodata: bool
    ray: dict[str, list[float]]
    selected: list[dict[str, Any]]
    hits: list[dict[str, Any]]
    road: dict[str, Any] | None


class GeolocateBatchResponse(_Response):
    """One answer per pixel, in order."""

    results: list[GeolocationOut]


# ----------------------------------------------------------------- detections
class DetectionBatch(_Request):
    """A batch of detection records from a camera process.

    Each record is ``{"t": s, "sensor": id, "bbox": [u_min, v_min, u_max, v_max],
    "class": "vehicle" | "human", "score": optional, "local_id": optional}`` (the
    detection JSON Lines format). ``t`` is UNIX seconds UTC (or, with the batch's
    ``epoch``, seconds after it); ``"time": "2026-12-01T14:32:05.25Z"`` (ISO 8601 with a
    zone) may stand for ``t``. Records are checked one by one; bad ones (a time without
    a zone among them) are skipped and counted by reason, the others stored. A record
    may carry ``pan_deg``, ``tilt_deg`` and ``hfov_deg``: its sensor's pose at ``t``,
    stored as pose telemetry (``poses`` in the acknowledgement counts them).
    """

    batch_key: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        description="client's id for the batch: a resent batch with a key already stored"
        " is acknowledged again and not stored twice",
    )
    detections: list[Any] = Field(description="detection records (see above)")
    epoch: str | None = Field(
        default=None,
        max_length=64,
        description="ISO 8601 time with a zone: the records' numeric t are seconds after it"
        " (a relative batch); default none, t are UNIX seconds",
    )

    @field_validator("epoch")
    @classmethod
    def _epoch_has_zone(cls, value: str | None) -> str | None:
        if value is not None:
            parse_iso_time(value, "epoch")
        return value

    @property
    def epoch_s(self) -> float | None:
        """The epoch as UNIX seconds (None: none declared)."""
        return None if self.epoch is None else parse_iso_time(self.epoch, "epoch")


class IngestIssueOut(_Response):
    """One skipped record (the first few per reason)."""

    index: int = Field(description="position of the record in the batch")
    reason: str
    message: str


class IngestAck(_Response):
    """Sent only after the batch's transaction has committed."""

    batch_id: int
    n_records: int
    accepted: int
    skipped: int
    counts: dict[str, int]
    issues: list[IngestIssueOut]
    detection_ids: list[int]
    duplicate: bool


class StoredDetectionOut(_Response):
    """A stored detection."""

    id: int
    t: float = Field(description="UNIX seconds, UTC")
    time_utc: str = Field(description="t as ISO 8601 UTC with Z (milliseconds)")
    sensor: str
    bbox: tuple[float, float, float, float]
    cls: str = Field(serialization_alias="class")
    score: float | None
    local_id: str | None


# --------------------------------------------------------------------- tracks
class TracksOut(_Response):
    """Tracks matching the filters, points clipped to the time window."""

    tracks: list[TrackBody]


class HealthOut(_Response):
    """Liveness and progress."""

    status: str
    schema_version: int
    last_seq: int
    counts: dict[str, int] | None = None
    viser_url: str | None = Field(
        default=None, description="the 3D scene (viser), or null when it is not served"
    )
