"""``sensor_pose`` messages: each sensor's newest pose, at most once per ``interval_s``.

A head may report poses at 25 Hz or more; consoles need a few a second to move a
footprint (the default interval is 0.2 s), and every message is stored in the event log.
After each committed batch the pipeline asks :meth:`PoseAnnouncer.due` for the sensors
whose poses changed: a sensor last announced at least ``interval_s`` ago (wall clock) is
announced now, with its newest pose; the others are marked and
:meth:`PoseAnnouncer.flush` announces their newest pose once their interval has passed
(the pipeline arms a timer for :meth:`PoseAnnouncer.next_flush_s`). So the newest pose
always goes out, a little late at worst, and never more than one message per sensor per
interval. The messages are stream messages: stored with a ``seq``, resumed.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from demtrack.core.camera.pose_series import PoseSample

from .stream_messages import SensorPosePayload

__all__ = ["DescribeFootprint", "PoseAnnouncer", "pose_payload"]

#: ``describe(sensor, sample)`` -> the ground footprint of the sensor at that pose (or None).
DescribeFootprint = Callable[[str, PoseSample], dict[str, Any] | None]


def pose_payload(
    sensor: str, p: PoseSample, describe: DescribeFootprint | None
) -> SensorPosePayload:
    """The ``sensor_pose`` message of ``sensor`` at pose ``p``."""
    return SensorPosePayload(
        sensor=sensor,
        t_s=float(p.t_s),
        pan_deg=float(p.pan_deg),
        tilt_deg=float(p.tilt_deg),
        roll_deg=float(p.roll_deg),
        hfov_deg=None if p.hfov_deg is None else float(p.hfov_deg),
        footprint=None if describe is None else describe(sensor, p),
    )


class PoseAnnouncer:
    """Rate-limited ``sensor_pose`` messages (see the module docstring).

    Parameters
    ----------
    interval_s : float
        Least wall-clock time between two messages of one sensor (s); 0: every batch.
    clock : callable
        Monotonic seconds (a test passes its own).
    """

    def __init__(self, interval_s: float = 0.1, clock: Callable[[], float] = time.monotonic):
        self.interval_s = float(interval_s)
        self.clock = clock
        #: ``describe(sensor, sample)``: the footprint each message carries (set by the app).
        self.describe: DescribeFootprint | None = None
        self._sent_at: dict[str, float] = {}
        self._sent_t: dict[str, float] = {}
        self._pending: set[str] = set()
        #: Messages made since start-up.
        self.n_sent = 0

    def _make(self, sensor: str, p: PoseSample, now: float) -> SensorPosePayload:
        self._sent_at[sensor] = now
        self._sent_t[sensor] = float(p.t_s)
        self._pending.discard(sensor)
        self.n_sent += 1
        return pose_payload(sensor, p, self.describe)

    def due(
        self, sensors: Iterable[str], newest: Mapping[str, PoseSample]
    ) -> list[tuple[str, SensorPosePayload]]:
        """Messages for ``sensors`` (whose poses changed) that may go now; mark the rest."""
        now = self.clock()
        out = []
        for s in sorted(set(sensors)):
            p = newest.get(s)
            if p is None or self._sent_t.get(s) == float(p.t_s):
                continue
            if now - self._sent_at.get(s, -float("inf")) >= self.interval_s:
                out.append(("sensor_pose", self._make(s, p, now)))
            else:
                self._pending.add(s)
        return out

    def next_flush_s(self) -> float | None:
        """Seconds until the first marked sensor may be announced (None: none marked)."""
        if not self._pending:
            return None
        now = self.clock()
        return max(0.0, min(self._sent_at[s] + self.interval_s - now for s in self._pending))

    def flush(self, newest: Mapping[str, PoseSample]) -> list[tuple[str, SensorPosePayload]]:
        """Messages for the marked sensors whose interval has passed."""
        now = self.clock()
        ready = [s for s in self._pending if now - self._sent_at[s] >= self.interval_s]
        return [("sensor_pose", self._make(s, newest[s], now)) for s in sorted(ready)]
