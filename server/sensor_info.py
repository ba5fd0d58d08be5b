"""What the sensor endpoints answer: each camera's pose, intrinsics and ground footprint.

Positions are site-frame ENU metres and WGS84 (``h_m`` above the ellipsoid); footprints
(border rays cast onto the DEM) are computed once per sensor pose. A sensor that reports
pose telemetry is shown at its newest pose (``pose``; ``pan_deg``, ``tilt_deg``, the
intrinsics and the footprint are that pose's), the others at their stored pan and tilt.
"""

from __future__ import annotations

import io
from pathlib import Path

from demtrack.core.camera.pose_series import PoseSeries
from demtrack.core.errors import NotFoundError
from demtrack.core.io.pose_io import write_poses_csv, write_poses_jsonl
from demtrack.core.io.times import format_utc
from demtrack.core.site.folder import Sensor

from .ingest.pose_book import pose_body, sample_from_body
from .models import SensorOut
from .state import ConsoleState
from .store.codec import dumps_json

__all__ = ["pose_export", "sensor_image_path", "sensor_out", "sensors_out"]


def sensor_out(state: ConsoleState, sensor: Sensor) -> SensorOut:
    """One sensor with its footprint (at its current pose, if it reports any)."""
    pose = state.poses.current(sensor.id)
    cam = state.poses.camera(sensor.id, pose)
    p = cam.position_enu
    lat, lon, h = state.site.frame.to_geodetic(float(p[0]), float(p[1]), float(p[2]))
    fp = state.poses.footprint_at(sensor.id, pose)
    intr = cam.intrinsics
    pose_out = None
    if pose is not None:
        pose_out = {**pose_body(pose), "time_utc": format_utc(pose.t_s, 3)}
    return SensorOut(
        id=sensor.id,
        name=sensor.name,
        position_enu=(float(p[0]), float(p[1]), float(p[2])),
        lat_deg=float(lat),
        lon_deg=float(lon),
        h_m=float(h),
        pan_deg=sensor.pan_deg if pose is None else pose.pan_deg,
        tilt_deg=sensor.tilt_deg if pose is None else pose.tilt_deg,
        width_px=intr.width,
        height_px=intr.height,
        intrinsics={k: float(v) for k, v in intr.to_dict().items()},
        image=sensor.image_path is not None,
        footprint=fp or {},
        active=bool(getattr(sensor, "active", False)),
        telemetry=state.pipeline.pose_book.driven(sensor.id),
        pose=pose_out,
    )


def sensors_out(state: ConsoleState) -> list[SensorOut]:
    """Every sensor, by id."""
    return [sensor_out(state, state.site.sensors[k]) for k in sorted(state.site.sensors)]


def sensor_image_path(state: ConsoleState, sensor_id: str) -> Path:
    """The still image named in ``site.json`` for the sensor.

    Chosen by sensor id, never by a path from the request, and checked to lie inside the
    site folder. :class:`~demtrack.core.errors.UnknownSensorError` for an unknown sensor,
    :class:`NotFoundError` when it has no (such) image.
    """
    sensor = state.site.sensor(sensor_id)
    path = sensor.image_path
    root = state.site.root.resolve()
    if path is None or not path.resolve().is_relative_to(root) or not path.is_file():
        raise NotFoundError(f"sensor {sensor_id!r} has no image")
    return path


def pose_export(
    state: ConsoleState,
    sensor_id: str,
    t_from: float | None,
    t_to: float | None,
    fmt: str,
) -> tuple[bytes, str]:
    """The stored poses of a sensor in ``[t_from, t_to]`` as a file: ``(bytes, media type)``.

    ``json``: ``{"sensor", "poses": [{t_s, time_utc, pan_deg, ...}]}``; ``csv`` and
    ``jsonl``: the pose file formats (:mod:`demtrack.core.io.pose_io`'s writer).
    """
    bodies = state.store.poses(sensor_id, t_from, t_to)
    if fmt == "json":
        poses = [{**b, "time_utc": format_utc(float(b["t_s"]), 3)} for b in bodies]
        return dumps_json({"sensor": sensor_id, "poses": poses}).encode(), "application/json"
    series = PoseSeries.from_samples([sample_from_body(b) for b in bodies])
    buf = io.StringIO()
    (write_poses_csv if fmt == "csv" else write_poses_jsonl)(buf, {sensor_id: series})
    return buf.getvalue().encode("utf-8"), "text/csv" if fmt == "csv" else "application/x-ndjson"
