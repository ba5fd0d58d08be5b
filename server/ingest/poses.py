"""Pose telemetry in: :class:`PoseIngest`, what the routers and head adapters call.

``state.poses.accept(sensor_id, samples, batch_key)`` stores a sensor's pose samples
durably (the acknowledgement comes once the transaction has committed, idempotent by
``batch_key`` like a detection batch: the same group commit, the same ``batches`` table),
merges them into the pipeline's rolling series of that sensor, geolocates the detections
that were waiting for them and announces the newest pose as a ``sensor_pose`` message
(rate-limited per sensor: :mod:`.pose_stream`). Records posted as JSON go through
:func:`~.pose_values.parse_pose_records` first (:meth:`PoseIngest.accept_records`).

The footprint a ``sensor_pose`` message and ``GET /api/sensors`` carry is the camera at
that pose cast onto the DEM (:func:`demtrack.server.footprints.footprint`), cached by pose.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

from demtrack.core.camera.pinhole import Camera
from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.raycast.cast import RayCaster

from ..footprints import footprint
from .pipeline import Pipeline
from .pose_values import ParsedPoses, parse_pose_records

__all__ = ["FOOTPRINT_CACHE", "POSE_FOOTPRINT", "PoseIngest"]

#: Footprints kept per server (most recently used).
FOOTPRINT_CACHE = 512
#: How a pose's footprint is drawn: 8 rays per image edge, points to the centimetre
#: (about 1.7 kB of JSON against 6 kB at 16 rays and full precision; each
#: ``sensor_pose`` message carries one and is stored in the event log).
POSE_FOOTPRINT: dict[str, Any] = {"per_edge": 8, "decimals": 2}


class PoseIngest:
    """The server's pose telemetry entry (``state.poses``).

    Parameters
    ----------
    pipeline : Pipeline
        Its pose book holds the series; its group commit stores the samples.
    caster : RayCaster, optional
        The DEM's ray caster, for footprints (none: messages carry no footprint).
    """

    def __init__(self, pipeline: Pipeline, caster: RayCaster | None = None) -> None:
        self.pipeline = pipeline
        self.site = pipeline.site
        self.caster = caster
        self._cache: OrderedDict[tuple[Any, ...], dict[str, Any]] = OrderedDict()
        self._cache_lock = threading.Lock()
        if caster is not None:
            pipeline.announcer.describe = self.footprint_at

    def accept(
        self,
        sensor_id: str,
        samples: Sequence[PoseSample] | ParsedPoses,
        batch_key: str | None = None,
    ) -> dict[str, Any]:
        """Store ``samples`` of ``sensor_id``; the acknowledgement (once committed).

        ``samples``: :class:`PoseSample` values (or the :class:`~.pose_values.ParsedPoses`
        of posted records). Returns ``batch_id``, ``n_records``, ``accepted``,
        ``skipped``, ``counts`` by reason, the first ``issues`` and ``duplicate``.

        Raises
        ------
        UnknownSensorError
            For a sensor the site does not have.
        """
        self.site.sensor(sensor_id)
        parsed = samples if isinstance(samples, ParsedPoses) else ParsedPoses.of(samples)
        ack = dict(self.pipeline.ingest_poses(sensor_id, parsed, batch_key))
        ack.pop("detection_ids", None)
        return ack

    def accept_records(
        self, sensor_id: str, records: Sequence[Any], batch_key: str | None = None
    ) -> dict[str, Any]:
        """:meth:`accept` for JSON records (:func:`~.pose_values.parse_pose_records`)."""
        sensor = self.site.sensor(sensor_id)
        head_u = float(sensor.head.position_enu[2])
        return self.accept(sensor_id, parse_pose_records(records, sensor_id, head_u), batch_key)

    # ------------------------------------------------------------------ views
    def current(self, sensor_id: str) -> PoseSample | None:
        """The sensor's newest stored pose (None: it never reported one)."""
        return self.pipeline.pose_book.newest.get(sensor_id)

    def camera(self, sensor_id: str, pose: PoseSample | None = None) -> Camera:
        """The sensor's camera at ``pose`` (default: its current one, else its fixed one)."""
        sensor = self.site.sensor(sensor_id)
        pose = pose if pose is not None else self.current(sensor_id)
        if pose is None:
            return sensor.camera
        return camera_at(sensor.head, pose, getattr(sensor, "zoom", None))

    def footprint_at(self, sensor_id: str, pose: PoseSample | None) -> dict[str, Any] | None:
        """The ground footprint of the sensor at ``pose`` (None without a caster), cached."""
        if self.caster is None:
            return None
        key = (sensor_id,) if pose is None else (sensor_id, *_pose_key(pose))
        with self._cache_lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                return hit
        cam = self.camera(sensor_id, pose)
        if pose is None:  # the fixed pose: computed once, full detail
            fp = footprint(cam, self.caster, self.site.frame)
        else:  # one per sensor_pose message, stored in the event log: compact
            fp = footprint(cam, self.caster, self.site.frame, **POSE_FOOTPRINT)
        with self._cache_lock:
            self._cache[key] = fp
            while len(self._cache) > FOOTPRINT_CACHE:
                self._cache.popitem(last=False)
        return fp


def _pose_key(p: PoseSample) -> tuple[Any, ...]:
    """What a footprint depends on: the pose without its time."""
    return (
        p.pan_deg,
        p.tilt_deg,
        p.roll_deg,
        p.hfov_deg,
        p.position_enu,
        p.platform_ypr_deg,
    )
