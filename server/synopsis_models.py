"""The ``/api/synopsis`` answer's schema: trajectories split into tracked parts and gaps.

Pydantic models only (the response model and its OpenAPI schema); the values are built
by :mod:`demtrack.server.synopsis`. Site-frame coordinates are ENU metres; ``h_m`` is
above the WGS84 ellipsoid; times are session seconds.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from .messages import EventBody

__all__ = [
    "GapPart",
    "SensorSpan",
    "SynopsisOut",
    "SynopsisPoint",
    "TrackedPart",
    "Trajectory",
]


class _Out(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SynopsisPoint(_Out):
    """A trajectory point: time (s), site frame (m), WGS84 (h above the ellipsoid)."""

    t_s: float
    e_m: float
    n_m: float
    u_m: float
    lat_deg: float
    lon_deg: float
    h_m: float


class SensorSpan(_Out):
    """When one sensor contributed to a tracked part."""

    sensor: str
    t_start_s: float
    t_end_s: float
    n_points: int


class TrackedPart(_Out):
    """A run of the trajectory with no gap."""

    kind: Literal["tracked"] = "tracked"
    t_start_s: float
    t_end_s: float
    duration_s: float
    sensors: list[str]
    sensor_spans: list[SensorSpan]
    n_points: int
    length_m: float = Field(description="horizontal path length (m)")
    path: list[SynopsisPoint] = Field(
        description="the run's points, at most one per step_s (first and last kept)"
    )


class GapPart(_Out):
    """A stretch where no sensor saw the target."""

    kind: Literal["gap"] = "gap"
    t_start_s: float
    t_end_s: float
    duration_s: float
    sensors_before: list[str] = Field(description="sensors of the last point before the gap")
    sensors_after: list[str] = Field(description="sensors of the first point after it")
    handoff: bool = Field(description="the target was picked up by a sensor that had not seen it")
    distance_m: float = Field(description="horizontal distance across the gap (m)")
    start: SynopsisPoint
    end: SynopsisPoint


Part = Annotated[TrackedPart | GapPart, Field(discriminator="kind")]


class Trajectory(_Out):
    """One track's long-term trajectory inside the window."""

    track_id: int
    cls: Literal["vehicle", "human"]
    live: bool
    t_start_s: float
    t_end_s: float
    duration_s: float
    sensors: list[str]
    n_points: int
    length_m: float
    n_gaps: int
    n_handoffs: int
    parts: list[Part] = Field(description="tracked parts and gaps in time order")
    event_ids: list[int] = Field(description="ids of the window's events involving it")


class SynopsisOut(_Out):
    """The synopsis of a time window."""

    t0: float | None
    t1: float | None
    n_trajectories: int
    n_gaps: int
    n_handoffs: int
    by_class: dict[str, int]
    events_by_kind: dict[str, int]
    trajectories: list[Trajectory]
    events: list[EventBody]
