"""The live server's tracks of a detection set, made offline: a replay through the pipeline.

``demtrack evaluate`` scores the batch trackers on a scenario's detections; what an operator
sees comes instead from the server's :class:`~.pipeline.Pipeline` - the detections posted
in batches, stored, their fixes made back from the stored bodies, held in the reorder
buffer and handed to the online tracker batch by batch. :func:`replay_detections` runs a
detection set through exactly that path, in-process, on a temporary SQLite store, in the
batching of the console's replay (:func:`~demtrack.server.replay.scenario_frames`
grouped into batches of ``batch_s`` scenario seconds: 0.1 s at 1x, 1 s at 10x with the
default 0.1 s wall-time batch interval), and returns the tracks the store then holds
(what the API serves) with the track events the stream announced. Moving cameras' pose
telemetry (``poses``) is posted with the batches, each batch's poses before its detections.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from demtrack.core.activity.kinds import EventKind
from demtrack.core.camera.pose_series import PoseSeries
from demtrack.core.errors import TrackingError
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Detection, Track, TrackPoint

from ..replay import scenario_frames
from ..store.database import Store
from .pipeline import Pipeline
from .pose_values import parse_pose_records

__all__ = ["LiveReplay", "early_ended", "replay_detections", "stubs", "track_from_body"]


@dataclass(frozen=True)
class LiveReplay:
    """What the server made of a replay.

    Parameters
    ----------
    tracks : tuple of Track
        The stored tracks, by id (``fix_indices`` are the store's detection ids).
    ended : tuple of (int, float)
        Each ``track_ended`` event streamed: ``(track id, t_s)``, in stream order.
    confirmed : tuple of (int, float)
        Each ``track_confirmed`` event streamed.
    n_batches : int
        Ingest calls made.
    """

    tracks: tuple[Track, ...]
    ended: tuple[tuple[int, float], ...]
    confirmed: tuple[tuple[int, float], ...]
    n_batches: int


def track_from_body(body: dict[str, Any]) -> Track:
    """The :class:`Track` of a stored track body (``GET /api/tracks``' form)."""
    points = tuple(
        TrackPoint(
            p["t_s"],
            np.array([p["e_m"], p["n_m"], p["u_m"]], dtype=np.float64),
            tuple(p["sensors"]),
            tuple(p["detection_ids"]),
        )
        for p in body["points"]
    )
    return Track(
        int(body["id"]),
        body["cls"],
        points,
        frozenset(body["sensors"]),
        tuple((float(a), float(b)) for a, b in body["gaps"]),
    )


def stubs(tracks: Sequence[Track], min_s: float = 5.0) -> list[Track]:
    """The tracks spanning less than ``min_s`` seconds from first to last point."""
    return [t for t in tracks if t.points and t.points[-1].t_s - t.points[0].t_s < min_s]


def early_ended(replay: LiveReplay) -> list[int]:
    """Ids announced ``track_ended`` that gained points after the announcement."""
    last = {t.id: t.points[-1].t_s for t in replay.tracks if t.points}
    return sorted({i for i, t in replay.ended if last.get(i, -np.inf) > t})


#: One ingest call: its detection records and each sensor's pose records.
Batch = tuple[list[dict[str, Any]], dict[str, list[dict[str, Any]]]]


def _batches(
    detections: Sequence[Detection],
    batch_s: float,
    poses: Mapping[str, PoseSeries] | None = None,
) -> list[Batch]:
    frames = scenario_frames(sorted(detections, key=lambda d: d.t_s), poses)
    out: list[Batch] = []
    k = 0
    while k < len(frames):
        j = k + 1
        # a frame belongs to the batch of the first frame less than batch_s before it
        while j < len(frames) and frames[j].t_s - frames[k].t_s < batch_s - 1e-9:
            j += 1
        by_sensor: dict[str, list[dict[str, Any]]] = {}
        for f in frames[k:j]:
            if f.poses:
                by_sensor.setdefault(f.sensor, []).extend(f.poses)
        out.append(([r for f in frames[k:j] for r in f.records], by_sensor))
        k = j
    return out


def replay_detections(
    site: Site,
    detections: Sequence[Detection],
    *,
    method: str = "kalman",
    batch_s: float = 0.1,
    reorder_lag_s: float = 0.5,
    db_dir: str | Path | None = None,
    poses: Mapping[str, PoseSeries] | None = None,
) -> LiveReplay:
    """Post ``detections`` to an in-process pipeline in batches; the tracks it stored.

    Parameters
    ----------
    site : Site
    detections : sequence of Detection
        Any order; sent per camera frame, in time order.
    method : str
        The server's tracking method.
    batch_s : float
        Scenario seconds of frames per ingest call (> 0; 0.1 is the 1x replay, 1.0 the
        10x one); ``math.inf`` sends everything at once.
    reorder_lag_s : float
        The server's reorder lag (s).
    db_dir : path, optional
        Folder of the temporary store (default: the system's temporary folder).
    poses : mapping of str to PoseSeries, optional
        Moving sensors' pose telemetry (``scenario.poses``), posted with the batches.
    """
    if not batch_s > 0:
        raise TrackingError(f"replay batch must be a positive number of seconds, got {batch_s}")
    ended: list[tuple[int, float]] = []
    confirmed: list[tuple[int, float]] = []

    def publish(messages: list[dict[str, Any]]) -> None:
        for m in messages:
            if m.get("type") != "event" or "event" not in m:
                continue
            ev = m["event"]
            if m["kind"] == EventKind.TRACK_ENDED.value:
                ended.append((int(ev["track_ids"][0]), float(ev["t_end_s"])))
            elif m["kind"] == EventKind.TRACK_CONFIRMED.value:
                confirmed.append((int(ev["track_ids"][0]), float(ev["t_start_s"])))

    batches = _batches(detections, batch_s, poses)
    with tempfile.TemporaryDirectory(dir=db_dir) as tmp:
        store = Store(Path(tmp) / "replay.sqlite3")
        try:
            # No wall clock in an offline replay: every batch's sensor_pose goes at once.
            pipeline = Pipeline(
                site, store, method, publish, reorder_lag_s=reorder_lag_s, pose_interval_s=0.0
            )
            pipeline.start()
            for records, by_sensor in batches:
                for sensor, recs in sorted(by_sensor.items()):
                    head_u = float(site.sensor(sensor).head.position_enu[2])
                    pipeline.ingest_poses(sensor, parse_pose_records(recs, sensor, head_u))
                if records:
                    pipeline.ingest(records)
            tracks = tuple(track_from_body(b) for b in store.tracks())
            pipeline.close()
        finally:
            store.close()
    return LiveReplay(tracks, tuple(ended), tuple(confirmed), len(batches))
