"""Live replay: scenarios fed into the ingest path as camera processes would.

A scenario (made by the :class:`~demtrack.server.scenario_source.ScenarioSource` the
caller hands over: the sample site's in ``demtrack serve`` and ``demtrack demo``) is a
time-ordered list of detections from genlocked cameras. The replay groups them into one
batch per camera per frame - what a camera process posts to ``POST /api/detections`` -
and hands each batch to :meth:`demtrack.server.pipeline.Pipeline.ingest`, the call that
route makes, paced by the wall clock at ``speed`` times real time. Going through the
pipeline rather than HTTP keeps the same validation, durable commit, geolocation,
tracking and publication, without loopback HTTP and JSON costs on a small machine and
without needing the port (which is only known once uvicorn is up when it binds port 0).
When ingest cannot keep up (a busy two-core machine, or a high speed), the frames already
due are sent together as one batch in time order - as a buffering camera gateway would -
so the replay holds its clock instead of drifting behind it.

Several scenarios play at once, each looping on its own period (its span plus a gap) so
the console always has something moving. Times are shifted so they start after the
newest time already stored (the ingest refuses a sensor's time going backwards) and grow
from loop to loop. For a busier scene (the console's soak benchmark keeps about 20 tracks
alive), each scenario can play as several copies staggered over its period, each with its
own noise seed; the cameras' frame rate and the replayed duration can be chosen too.

A scenario of moving (PTZ) cameras carries each sensor's pose telemetry
(``scenario.poses``: sensor id -> :class:`~demtrack.core.camera.pose_series.PoseSeries`;
none when absent). Its samples ride in the frames at their own times (``ReplayFrame.poses``)
and each batch's poses are posted (``send_poses``, e.g. :meth:`PoseIngest.accept_records
<demtrack.server.ingest.poses.PoseIngest.accept_records>`) before its detections, per
sensor in time order, as a head's telemetry would arrive ahead of the video it covers.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from demtrack.core.camera.pose_series import PoseSample, PoseSeries
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Detection

from .replay_schedule import replay_schedule
from .scenario_source import ReplayScenario, ScenarioSource

__all__ = [
    "Replay",
    "ReplayFrame",
    "detection_record",
    "loop_frames",
    "merge_frames",
    "pose_record",
    "scenario_copies",
    "scenario_frames",
    "scenario_stream",
    "start_time_after",
]

log = logging.getLogger("demtrack.server")

#: Seconds of silence between two loops of one scenario (tracks end, then start anew).
LOOP_GAP_S = 5.0


@dataclass(frozen=True)
class ReplayFrame:
    """One camera's batch for one frame.

    Parameters
    ----------
    t_s : float
        Frame time on the replay clock (s).
    sensor : str
        Camera id.
    records : tuple of dict
        Detection records in the ingest format (``{"t", "sensor", "bbox", "class",
        "score"?, "local_id"?}``), all at ``t_s`` from ``sensor``.
    poses : tuple of dict
        Pose records of ``sensor`` at ``t_s`` in the pose ingest format (``{"t",
        "pan_deg", "tilt_deg", "hfov_deg"?, ...}``); empty for a fixed camera.
    """

    t_s: float
    sensor: str
    records: tuple[dict[str, Any], ...]
    poses: tuple[dict[str, Any], ...] = ()


def detection_record(d: Detection, t_s: float | None = None) -> dict[str, Any]:
    """The ingest record of a detection, at time ``t_s`` (default: its own)."""
    rec: dict[str, Any] = {
        "t": d.t_s if t_s is None else t_s,
        "sensor": d.sensor,
        "bbox": [float(x) for x in d.bbox],
        "class": d.cls,
    }
    if d.score is not None:
        rec["score"] = d.score
    if d.local_id is not None:
        rec["local_id"] = d.local_id
    return rec


def pose_record(p: PoseSample) -> dict[str, Any]:
    """The pose ingest record of a sample (``POST /api/sensors/{id}/poses``)."""
    rec: dict[str, Any] = {"t": p.t_s, "pan_deg": p.pan_deg, "tilt_deg": p.tilt_deg}
    if p.hfov_deg is not None:
        rec["hfov_deg"] = p.hfov_deg
    if p.roll_deg:
        rec["roll_deg"] = p.roll_deg
    if p.position_enu is not None:
        rec["e_m"], rec["n_m"], rec["u_m"] = p.position_enu
    if p.platform_ypr_deg is not None:
        rec["yaw_deg"], rec["pitch_deg"], rec["platform_roll_deg"] = p.platform_ypr_deg
    return rec


def scenario_frames(
    detections: Sequence[Detection], poses: Mapping[str, PoseSeries] | None = None
) -> list[ReplayFrame]:
    """Group a scenario's detections (and poses) into per-camera, per-frame batches.

    Parameters
    ----------
    detections : sequence of Detection
        In time order (as a :class:`~demtrack.server.scenario_source.ScenarioSource` makes
        them).
    poses : mapping of str to PoseSeries, optional
        Each moving sensor's pose telemetry (``scenario.poses``).

    Returns
    -------
    list of ReplayFrame
        Ordered by ``(t_s, sensor)``; records keep the scenario's own times.
    """
    groups: dict[tuple[float, str], tuple[list[dict[str, Any]], list[dict[str, Any]]]] = {}
    for d in detections:
        groups.setdefault((float(d.t_s), d.sensor), ([], []))[0].append(detection_record(d))
    for sensor, series in (poses or {}).items():
        for p in series.samples():
            groups.setdefault((float(p.t_s), sensor), ([], []))[1].append(pose_record(p))
    return [
        ReplayFrame(t, s, tuple(recs), tuple(ps)) for (t, s), (recs, ps) in sorted(groups.items())
    ]


def _shifted(frame: ReplayFrame, shift_s: float) -> ReplayFrame:
    # Rounded to the microsecond so shifted frame times do not drift in the last bits.
    t = round(frame.t_s + shift_s, 6)
    poses = tuple({**p, "t": round(p["t"] + shift_s, 6)} for p in frame.poses)
    return ReplayFrame(t, frame.sensor, tuple({**r, "t": t} for r in frame.records), poses)


def loop_frames(
    frames: Sequence[ReplayFrame],
    t0_s: float,
    *,
    loop: bool = True,
    gap_s: float = LOOP_GAP_S,
    period_s: float | None = None,
) -> Iterator[ReplayFrame]:
    """One scenario's frames with its time 0 moved to ``t0_s``, repeated if ``loop``.

    Loop ``k`` is shifted by ``t0_s + k * period`` with ``period = period_s`` or, by
    default, ``t_last + gap_s`` (scenario times start at 0), so every sensor's times keep
    growing and a replayed time minus the shift is the scenario's own time (its truth
    lines up).
    """
    if not frames:
        return
    period = max(frames[-1].t_s, 0.0) + gap_s if period_s is None else float(period_s)
    for k in itertools.count() if loop else range(1):
        shift = t0_s + k * period
        for f in frames:
            yield _shifted(f, shift)


def merge_frames(streams: Iterable[Iterable[ReplayFrame]]) -> Iterator[ReplayFrame]:
    """Merge time-ordered frame streams into one, ordered by ``(t_s, sensor)``.

    Two scenarios' batches for the same camera and frame are joined into one batch.
    """
    merged = heapq.merge(*streams, key=lambda f: (f.t_s, f.sensor))
    pending: ReplayFrame | None = None
    for f in merged:
        if pending is not None and (f.t_s, f.sensor) == (pending.t_s, pending.sensor):
            pending = ReplayFrame(
                f.t_s, f.sensor, pending.records + f.records, pending.poses + f.poses
            )
            continue
        if pending is not None:
            yield pending
        pending = f
    if pending is not None:
        yield pending


def start_time_after(last_times: dict[str, float], gap_s: float = LOOP_GAP_S) -> float:
    """The replay's first frame time: a whole second at least ``gap_s`` after ``last_times``.

    Parameters
    ----------
    last_times : dict
        Sensor id -> newest stored detection time (s); empty for a fresh store.
    """
    if not last_times:
        return 0.0
    return float(math.ceil(max(last_times.values()) + gap_s))


def scenario_copies(
    site: Site,
    names: Sequence[str],
    copies: int,
    rate_hz: float | None = None,
    *,
    source: ScenarioSource,
) -> tuple[list[tuple[str, list[ReplayScenario]]], float]:
    """Each named scenario's copies (copy ``k`` with noise seed ``k``) and the frame rate.

    ``rate_hz``: the cameras' frame rate (default: the scenarios' own, ``source.rate_hz``);
    ``source`` makes the scenarios.
    """
    made = []
    for name in names:
        made.append(
            (name, [source.make(site, name, seed=k, rate_hz=rate_hz) for k in range(copies)])
        )
    return made, source.rate_hz if rate_hz is None else rate_hz


def scenario_stream(
    site: Site,
    names: Sequence[str],
    t0_s: float,
    *,
    source: ScenarioSource,
    loop: bool = True,
    gap_s: float = LOOP_GAP_S,
    copies: int = 1,
    rate_hz: float | None = None,
    duration_s: float | None = None,
) -> Iterator[ReplayFrame]:
    """Frames of the named scenarios played together from ``t0_s``.

    Each scenario is generated by ``source`` (the sample site's: default noise, about a
    second each) and loops on its own period.

    Parameters
    ----------
    source : ScenarioSource
        Makes the scenarios (``demtrack.samplesite.replay_source.SAMPLE_SCENARIOS``).
    copies : int
        Copies of each scenario, copy ``k`` made with noise seed ``k`` and started
        ``k / copies`` of the scenario's period after copy 0, rounded to a whole frame so
        the copies' frames share batches. Periods (at least span plus ``gap_s``) and each
        scenario's phase come from
        :func:`~demtrack.server.replay_schedule.replay_schedule`: the loops stay in step
        and no two vehicles of different scenarios are ever on top of each other.
    rate_hz : float, optional
        The cameras' frame rate (default: the scenarios' own, 10 Hz).
    duration_s : float, optional
        Stop after this much replayed time (s after ``t0_s``); default: no end.

    Raises
    ------
    SiteError
        From the sample site's source: an unknown scenario, or a site that is not a
        generated sample site.
    ValueError
        ``copies`` below 1.
    """
    if copies < 1:
        raise ValueError(f"replay copies must be at least 1, got {copies}")
    played = []  # per scenario: each copy's frames, copy 0's truths
    made, rate = scenario_copies(site, names, copies, rate_hz, source=source)
    for _, scenarios in made:
        frames = [scenario_frames(sc.detections, getattr(sc, "poses", None)) for sc in scenarios]
        if frames[0]:
            played.append((frames, scenarios[0].truths))
    if not played:
        return iter(())
    periods, offsets = replay_schedule(
        [max(f[0][-1].t_s, 0.0) for f, _ in played], [tr for _, tr in played], copies, rate, gap_s
    )
    streams = [
        loop_frames(frames[k], t0_s + offsets[j][k], loop=loop, period_s=periods[j])
        for j, (frames, _) in enumerate(played)
        for k in range(copies)
        if frames[k]
    ]
    merged = merge_frames(streams)
    if duration_s is None:
        return merged
    return itertools.takewhile(lambda f: f.t_s < t0_s + duration_s, merged)


class Replay:
    """Feeds frames to ``send`` in a daemon thread, paced at ``speed`` x real time.

    Parameters
    ----------
    make_frames : callable
        Returns the frames to play (an iterable in time order, possibly endless). Called
        in the replay thread, so slow scenario generation does not hold up start-up.
    send : callable
        ``send(records)`` ingests one batch (e.g. :meth:`Pipeline.ingest`) and returns
        its acknowledgement (a dict with ``accepted``).
    send_poses : callable, optional
        ``send_poses(sensor, records)`` ingests one sensor's pose records; called for a
        batch's poses (per sensor, in time order) before its detections. None: the
        frames' poses are dropped.
    speed : float
        Replay-clock seconds per wall-clock second (> 0).
    max_lag_s : float
        When sending falls this far behind the clock (a slow machine), the clock is
        moved on instead of sending a burst to catch up.
    max_coalesce : int
        When ingest cannot keep up, the frames already due (up to this many) are sent as
        one batch, in time order, instead of one batch per camera per frame.
    min_interval_s : float
        Wall time (s) from one batch's sending to the next: frames that fall due in
        between wait and go together, as from a camera gateway that buffers this long.
        A batch's cost is largely fixed (one transaction, every changed track encoded and
        published once, the tracker's flush), so at 10x speed batches of the frames of
        0.1 s of wall time cost far less per detection than one or two frames each, which
        is what an ingest that only just keeps up settles to. 0 sends each frame when due.
    clock : callable
        Monotonic wall clock (s).

    Attributes
    ----------
    n_batches, n_frames, n_records, n_accepted : int
        Batches sent, frames in them, records in them, records the ingest accepted.
    t_s : float or None
        Time of the last frame sent.
    error : BaseException or None
        What stopped the replay early, if anything.
    """

    def __init__(
        self,
        make_frames: Callable[[], Iterable[ReplayFrame]],
        send: Callable[[list[dict[str, Any]]], Any],
        *,
        send_poses: Callable[[str, list[dict[str, Any]]], Any] | None = None,
        speed: float = 1.0,
        max_lag_s: float = 2.0,
        max_coalesce: int = 240,
        min_interval_s: float = 0.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"replay speed must be a positive number, got {speed}")
        self.make_frames = make_frames
        self.send = send
        self.send_poses = send_poses
        self.speed = float(speed)
        self.max_lag_s = float(max_lag_s)
        self.max_coalesce = max(1, int(max_coalesce))
        if not (math.isfinite(min_interval_s) and min_interval_s >= 0):
            raise ValueError(
                f"replay batch interval must be a number of seconds >= 0, got {min_interval_s}"
            )
        self.min_interval_s = float(min_interval_s)
        self.clock = clock
        self.n_batches = 0
        self.n_frames = 0
        self.n_records = 0
        self.n_accepted = 0
        self.t_s: float | None = None
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        """Whether the replay thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> Replay:
        """Start the replay thread (once)."""
        if self._thread is not None:
            raise RuntimeError("replay already started")
        self._thread = threading.Thread(target=self._run, name="demtrack-replay", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 10.0) -> bool:
        """Ask the thread to stop after the batch in flight; True once it has ended."""
        self._stop.set()
        if self._thread is None:
            return True
        self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def _run(self) -> None:
        try:
            self._play(self.make_frames())
        except BaseException as exc:  # noqa: BLE001 - reported, never raised in a thread
            self.error = exc
            log.error("replay stopped: %s", exc)

    def _send_poses(self, batch: Sequence[ReplayFrame]) -> None:
        """Post the poses of ``batch``'s frames, one call per sensor, in time order."""
        if self.send_poses is None:
            return
        by_sensor: dict[str, list[dict[str, Any]]] = {}
        for f in batch:
            if f.poses:
                by_sensor.setdefault(f.sensor, []).extend(f.poses)
        for sensor, recs in sorted(by_sensor.items()):
            self.send_poses(sensor, sorted(recs, key=lambda r: r["t"]))

    def _play(self, frames: Iterable[ReplayFrame]) -> None:
        it = iter(frames)
        frame = next(it, None)
        if frame is None:
            return
        wall0, t0 = self.clock(), frame.t_s

        def due(f: ReplayFrame) -> float:
            return wall0 + (f.t_s - t0) / self.speed

        next_send = -math.inf  # wall time the next batch may go (min_interval_s)
        while frame is not None and not self._stop.is_set():
            now = self.clock()
            wait = due(frame) - now
            hold = max(wait, next_send - now)
            if hold > 0 and self._stop.wait(hold):
                return
            if -wait > self.max_lag_s:
                wall0 += -wait  # far behind: move the clock on rather than burst
            # Frames already due go together, as a buffering camera gateway sends them.
            batch = [frame]
            frame = next(it, None)
            now = self.clock()
            while frame is not None and len(batch) < self.max_coalesce and due(frame) <= now:
                batch.append(frame)
                frame = next(it, None)
            # The next batch waits out the interval, unless this one left due frames behind
            # (max_coalesce): those go at once, or the interval would cap the pace.
            behind = frame is not None and due(frame) <= now
            records = [r for f in batch for r in f.records]
            # The interval runs from the send itself, not from the batch's assembly.
            next_send = -math.inf if behind else self.clock() + self.min_interval_s
            self._send_poses(batch)
            if not records and any(f.poses for f in batch):
                self.t_s = batch[-1].t_s  # poses only: no detection batch to post
                continue
            ack = self.send(records)
            self.n_batches += 1
            self.n_frames += len(batch)
            self.n_records += len(records)
            self.n_accepted += int(ack.get("accepted", 0)) if isinstance(ack, dict) else 0
            self.t_s = batch[-1].t_s
