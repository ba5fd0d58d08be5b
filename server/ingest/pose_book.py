"""The pipeline's pose telemetry: checked samples, each sensor's rolling series, deferral.

A sensor is *telemetry-driven* when the site marks it ``active`` or once any pose of it
has been stored (a fixed camera that reports poses becomes one); its detections are
geolocated with the pose of their own moment (:func:`~demtrack.core.geolocation.
fix_builder.build_fixes` with ``poses``), never with its stored pan and tilt. Other
sensors keep their fixed camera.

Poses go forwards in time per sensor: a sample not newer than the sensor's newest stored
one is skipped (``time_backwards`` / ``duplicate_time``), as is one whose optional parts
(zoom, position, platform attitude) differ from the sensor's series (``mixed_fields``),
after the pose reader's own checks of each record (:mod:`.pose_values`). Each
sensor's series keeps the last :data:`WINDOW_S` of samples in memory (trimmed when it
holds twice that).

Deferral: a telemetry-driven detection waits (unprocessed, stored) until its pose is
settled - a sample exists at or after its lookup time ``t + pose_latency_s``, so no later
sample can change the interpolation - or until it falls behind the reorder horizon (the
newest detection time minus the reorder lag), when it is geolocated with what there is or
counted ``no_pose``. Both tests read only what is stored, so a restart that reloads the
stored poses before the unprocessed detections decides exactly as the live run did.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from demtrack.core.camera.pose_series import PoseSample, PoseSeries
from demtrack.core.errors import DemtrackError
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Detection

from ..store.poses import PoseRow
from .pose_values import ParsedPoses
from .validate import MAX_ISSUES

__all__ = [
    "POSE_REASONS",
    "WINDOW_S",
    "PoseBook",
    "pose_body",
    "sample_from_body",
    "sensor_pose_settings",
]

#: Seconds of poses each sensor's in-memory series keeps (behind its newest sample).
WINDOW_S = 600.0
#: Reasons a sample the reader accepted is still skipped (against the stored poses), in
#: the order they are checked; the reader's own are :data:`demtrack.core.io.pose_io.POSE_REASONS`.
POSE_REASONS = ("nan", "time_backwards", "duplicate_time", "mixed_fields")


def _shape(p: PoseSample) -> tuple[bool, bool, bool]:
    """Which optional parts a sample has: zoom, position, platform attitude."""
    return (p.hfov_deg is not None, p.position_enu is not None, p.platform_ypr_deg is not None)


def sensor_pose_settings(site: Site, sensor: str) -> tuple[bool, float, float]:
    """``(active, max_pose_gap_s, pose_latency_s)`` of a sensor (defaults: False, 0.2, 0)."""
    s = site.sensors.get(sensor)
    if s is None:
        return False, 0.2, 0.0
    gap = getattr(s, "max_pose_gap_s", None)
    lat = getattr(s, "pose_latency_s", None)
    return (
        bool(getattr(s, "active", False)),
        0.2 if gap is None else float(gap),
        0.0 if lat is None else float(lat),
    )


def pose_body(p: PoseSample) -> dict[str, Any]:
    """The stored JSON body of a sample (degrees; ``position_enu``: site frame, m)."""
    body: dict[str, Any] = {
        "t_s": float(p.t_s),
        "pan_deg": float(p.pan_deg),
        "tilt_deg": float(p.tilt_deg),
        "hfov_deg": None if p.hfov_deg is None else float(p.hfov_deg),
        "roll_deg": float(p.roll_deg),
    }
    if p.position_enu is not None:
        body["position_enu"] = [float(x) for x in np.asarray(p.position_enu, dtype=float)]
    if p.platform_ypr_deg is not None:
        body["platform_ypr_deg"] = [float(x) for x in np.asarray(p.platform_ypr_deg, dtype=float)]
    return body


def sample_from_body(body: Mapping[str, Any]) -> PoseSample:
    """The sample of a stored body (the inverse of :func:`pose_body`)."""
    pos = body.get("position_enu")
    ypr = body.get("platform_ypr_deg")
    return PoseSample(
        float(body["t_s"]),
        float(body["pan_deg"]),
        float(body["tilt_deg"]),
        hfov_deg=None if body.get("hfov_deg") is None else float(body["hfov_deg"]),
        roll_deg=float(body.get("roll_deg") or 0.0),
        position_enu=None if pos is None else tuple(float(x) for x in pos),
        platform_ypr_deg=None if ypr is None else tuple(float(x) for x in ypr),
    )


def _finite(p: PoseSample) -> bool:
    vals = [p.t_s, p.pan_deg, p.tilt_deg, p.roll_deg]
    if p.hfov_deg is not None:
        vals.append(p.hfov_deg)
    for extra in (p.position_enu, p.platform_ypr_deg):
        if extra is not None:
            vals += [float(x) for x in np.asarray(extra, dtype=float).ravel()]
    return all(math.isfinite(float(v)) for v in vals)


class PoseBook:
    """Stored-pose bookkeeping of one pipeline (see the module docstring).

    Attributes
    ----------
    series : dict of str to PoseSeries
        Each telemetry sensor's recent poses.
    last_t : dict of str to float
        Each sensor's newest stored pose time (s): the order check of the next sample.
    newest : dict of str to PoseSample
        Each sensor's newest stored sample (its current pose).
    waiting : dict of int to Detection
        Stored telemetry detections not yet geolocated, by detection id.
    """

    def __init__(self, site: Site, window_s: float = WINDOW_S) -> None:
        self.site = site
        self.window_s = float(window_s)
        self.series: dict[str, PoseSeries] = {}
        self.last_t: dict[str, float] = {}
        self.newest: dict[str, PoseSample] = {}
        self.waiting: dict[int, Detection] = {}
        #: Detections counted ``no_pose`` (geolocated never: no pose close enough).
        self.n_no_pose = 0
        #: Pose samples stored since start-up and skipped, by reason.
        self.n_stored = 0
        self.n_skipped = 0

    # ------------------------------------------------------------------ checks
    def driven(self, sensor: str) -> bool:
        """Whether ``sensor``'s detections are geolocated with telemetry."""
        return sensor in self.last_t or sensor_pose_settings(self.site, sensor)[0]

    def check(
        self, sensor: str, parsed: ParsedPoses, *, quiet_duplicates: bool = False
    ) -> tuple[list[PoseSample], dict[str, Any]]:
        """The samples of ``parsed`` to store (advancing :attr:`last_t`) and the counts.

        ``parsed``: what the reader accepted and skipped; its samples then meet the
        stored ones (time order, optional parts). With ``quiet_duplicates`` a sample at
        the time of the one before it is dropped without being counted (the inline poses
        of one frame's detections).
        """
        counts = dict(parsed.counts)
        issues = list(parsed.issues)
        kept: list[PoseSample] = []
        last = self.last_t.get(sensor, -math.inf)
        held = self.newest.get(sensor)
        shape = None if held is None else _shape(held)

        def skip(i: int, reason: str, message: str) -> None:
            counts[reason] = counts.get(reason, 0) + 1
            if len(issues) < MAX_ISSUES:
                issues.append({"index": i, "reason": reason, "message": message})

        for i, p in enumerate(parsed.samples):
            if not _finite(p):
                skip(i, "nan", f"a pose of {sensor} holds NaN or infinity")
                continue
            if quiet_duplicates and p.t_s == last:
                continue  # another detection of the same frame (or of the last one stored)
            if p.t_s < last:
                skip(i, "time_backwards", f"t={p.t_s} s is before {sensor}'s newest pose")
                continue
            if p.t_s == last:
                skip(i, "duplicate_time", f"{sensor} already has a pose at t={p.t_s} s")
                continue
            if shape is not None and _shape(p) != shape:
                skip(i, "mixed_fields", f"optional fields differ from {sensor}'s series")
                continue
            kept.append(p)
            last = p.t_s
            shape = _shape(p)
        if kept:
            self.last_t[sensor] = last
        issues.sort(key=lambda e: e["index"])
        ack = {
            "n_records": parsed.n_records,
            "accepted": len(kept),
            "skipped": sum(counts.values()),
            "counts": {k: v for k, v in counts.items() if v},
            "issues": issues,
        }
        self.n_skipped += ack["skipped"]
        return kept, ack

    @staticmethod
    def rows(sensor: str, samples: Iterable[PoseSample]) -> list[PoseRow]:
        """The store rows of ``samples``."""
        return [(sensor, float(p.t_s), pose_body(p)) for p in samples]

    # ----------------------------------------------------------------- series
    def extend(self, sensor: str, samples: Sequence[PoseSample]) -> None:
        """Add stored ``samples`` (time order, newer than what is held) to the series."""
        if not samples:
            return
        old = self.series.get(sensor)
        s = PoseSeries.from_samples(list(samples)) if old is None else old.extended(samples)
        newest_t = float(samples[-1].t_s)
        if len(s) > 1 and float(s.t_s[0]) < newest_t - 2.0 * self.window_s:
            s = s.since(newest_t - self.window_s)
        self.series[sensor] = s
        self.newest[sensor] = samples[-1]
        self.n_stored += len(samples)

    def load(
        self, bodies: Mapping[str, Sequence[Mapping[str, Any]]], last_t: Mapping[str, float]
    ) -> None:
        """Start from the stored poses: the recent window of each sensor and newest times."""
        self.last_t = dict(last_t)
        for sensor, rows in sorted(bodies.items()):
            samples = [sample_from_body(b) for b in rows]
            if samples:
                self.series[sensor] = PoseSeries.from_samples(samples)
                self.newest[sensor] = samples[-1]

    # --------------------------------------------------------------- deferral
    def settled(self, d: Detection) -> bool:
        """Whether no pose still to come can change ``d``'s interpolated pose."""
        _, _, latency = sensor_pose_settings(self.site, d.sensor)
        return self.last_t.get(d.sensor, -math.inf) >= d.t_s + latency

    def split(
        self, pending: Sequence[tuple[int, Detection]], horizon_t: float
    ) -> list[tuple[int, Detection]]:
        """What to geolocate now: ``pending`` and the waiting ones that are due, by id.

        Telemetry detections neither settled nor behind ``horizon_t`` (s) wait.
        """
        for det_id, d in pending:
            self.waiting[det_id] = d
        now: list[tuple[int, Detection]] = []
        for det_id in sorted(self.waiting):
            d = self.waiting[det_id]
            if not self.driven(d.sensor) or d.t_s <= horizon_t or self.settled(d):
                now.append((det_id, d))
        for det_id, _ in now:
            del self.waiting[det_id]
        return now

    def for_fixes(self, dets: Sequence[Detection]) -> dict[str, PoseSeries]:
        """The series to geolocate ``dets`` with: every telemetry sensor among them.

        A telemetry sensor with no pose yet gets an empty-handed answer from
        :meth:`no_pose` instead (it is not in the mapping: the caller drops its
        detections before geolocating).
        """
        sensors = {d.sensor for d in dets}
        return {s: self.series[s] for s in sensors if s in self.series and self.driven(s)}

    def no_pose(self, dets: Sequence[Detection]) -> np.ndarray:
        """Bool mask of ``dets`` that are telemetry-driven and have no pose close enough."""
        out = np.zeros(len(dets), dtype=bool)
        by_sensor: dict[str, list[int]] = {}
        for i, d in enumerate(dets):
            if self.driven(d.sensor):
                by_sensor.setdefault(d.sensor, []).append(i)
        for sensor, idx in by_sensor.items():
            series = self.series.get(sensor)
            if series is None:
                out[idx] = True
                continue
            _, gap, latency = sensor_pose_settings(self.site, sensor)
            t = np.array([dets[i].t_s for i in idx], dtype=np.float64)
            try:
                ok = np.asarray(series.at(t, max_gap_s=gap, latency_s=latency).ok, dtype=bool)
            except DemtrackError:
                ok = np.zeros(len(idx), dtype=bool)
            out[idx] = ~ok
        return out
