"""The pipeline's coordinator: one batch through store, fixes, tracker, events and stream.

One :class:`Pipeline` per server, called from worker threads; a lock serialises batches
so detection ids, the tracker's input order and the stream's sequence numbers all follow
arrival order (:mod:`.group_commit`). The tracker's input is always the fix *as stored*
(:mod:`.fix_codec`), fed through the reorder buffer (:mod:`.reorder`,
:mod:`.tracker_feed`), so replaying the stored fixes at start-up (:mod:`.replay_on_start`)
rebuilds exactly the tracker state the live run had. After each batch
:class:`~demtrack.server.live_events.LiveEvents` may run the activity detectors and
hand-off prediction (every ``every_s`` of scenario time); its events are stored in the
``activity`` table and streamed as ``event`` messages (:mod:`.events`). Each job lives in
its own module; this one wires them together.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from demtrack.core.activity.convoy import ConvoyParams
from demtrack.core.activity.kinds import EventKind
from demtrack.core.activity.loitering import LoiterParams
from demtrack.core.activity.rendezvous import RendezvousParams
from demtrack.core.geolocation.fix_builder import sensor_sizes
from demtrack.core.site.folder import Site
from demtrack.core.site.zone_io import read_zones_geojson
from demtrack.core.tracking import build_tracker
from demtrack.core.tracking.types import Detection, Fix, Track

from ..live_events import LiveEventParams, LiveEvents
from ..store.backend import StoreBackend
from ..store.derived import FixRow
from ..store.integrity import StoreUnavailableError
from .events import event_message, ingest_message
from .fix_codec import fix_bodies, tracker_fixes
from .group_commit import Ack, GroupCommit, Request, commit_group
from .held_writes import HeldWrites
from .pose_book import WINDOW_S, PoseBook, geolocate_posed, sample_from_body
from .pose_stream import PoseAnnouncer
from .pose_values import ParsedPoses
from .publish import Publisher, sensor_status_messages
from .reorder import ReorderBuffer
from .replay_on_start import load_stored_fixes
from .stream_messages import EventPayload, FixPayload, StreamPayload
from .track_bodies import Geodetic, TrackBodies
from .tracker_feed import TrackerFeed
from .validate import validate_records

__all__ = ["CATCH_UP_CHUNK", "Pipeline", "Publisher", "pipeline_options"]

log = logging.getLogger("demtrack.server")

#: Detections of other processes' batches read per query (:meth:`Pipeline.catch_up`).
CATCH_UP_CHUNK = 5000


def pipeline_options(settings: Any) -> dict[str, Any]:
    """Keyword arguments of :class:`Pipeline` from the server settings.

    Zones come from ``settings.zones_path`` or, when unset, ``<site>/zones.geojson`` if
    that file exists (read in the site's frame).
    """
    return {
        "reorder_lag_s": settings.reorder_lag_s,
        "retain_ended_s": settings.track_retain_s,
        "events": (
            LiveEventParams(
                every_s=settings.events_every_s,
                window_s=settings.events_window_s,
                sample_s=settings.events_sample_s,
                loiter=LoiterParams(settings.loiter_radius_m, settings.loiter_min_s),
                rendezvous=RendezvousParams(
                    settings.rendezvous_distance_m,
                    settings.rendezvous_stop_mps,
                    settings.rendezvous_min_s,
                ),
                convoy=ConvoyParams(
                    path_tolerance_m=settings.convoy_path_tolerance_m,
                    max_lag_s=settings.convoy_max_lag_s,
                    min_distance_m=settings.convoy_min_distance_m,
                ),
                handoff_horizon_s=settings.handoff_horizon_s,
                handoff_dt_s=settings.handoff_dt_s,
            )
            if settings.events
            else None
        ),
        "zones_path": settings.zones_path or settings.site / "zones.geojson",
        "pose_interval_s": settings.pose_message_interval_s,
    }


class Pipeline:
    """The server's ingest and tracking state.

    Parameters
    ----------
    site : Site
    store : StoreBackend
    method : str
        Tracking method (a key of :data:`demtrack.core.tracking.METHODS`).
    publish : callable
        Receives each batch's stream messages, in sequence order.
    reorder_lag_s : float
        How far behind the newest fix a fix waits before it is tracked (s).
    events : LiveEventParams or None
        Live activity detection and hand-off prediction; None turns them off.
    zones_path : path, optional
        GeoJSON zones for enter/leave events (ignored when the file does not exist).
    retain_ended_s : float
        Forget ended tracks whose last fix is more than this far behind the newest
        tracked one (s; at least the tracker's re-acquisition window and the live events'
        window are kept). They stay in the store.
    pose_interval_s : float
        Least wall-clock time between two ``sensor_pose`` messages of one sensor (s).
    """

    def __init__(
        self,
        site: Site,
        store: StoreBackend,
        method: str,
        publish: Publisher,
        *,
        reorder_lag_s: float = 0.5,
        events: LiveEventParams | None = None,
        zones_path: Any = None,
        retain_ended_s: float = 600.0,
        pose_interval_s: float = 0.2,
    ) -> None:
        self.site = site
        self.store = store
        self.method = method
        self.publish = publish
        self.sizes = sensor_sizes(site)
        self.reorder_lag_s = float(reorder_lag_s)
        self.retain_ended_s = float(retain_ended_s)
        if events is not None and zones_path is not None and Path(zones_path).is_file():
            zones = tuple(read_zones_geojson(zones_path, site.frame))
            events = LiveEventParams(**{**events.__dict__, "zones": zones})
        self.event_params = events
        self.commits = GroupCommit()
        #: Ingest transactions committed and the batches they held (group commit).
        self.n_commits = 0
        self.n_batches = 0
        self._last_t: dict[str, float] = {}
        self._n_det: dict[str, int] = {}
        self._pose_interval_s = float(pose_interval_s)
        #: Derived writes in order; those a full store refused wait for space.
        self.writes = self._held_writes()
        self._fresh_tracking()
        self._flush_timer: threading.Timer | None = None
        self._inline: dict[str, Any] | None = None
        self._closed = False
        #: Whether batches are tracked after their commit. False on a follower of a
        #: cluster (:mod:`demtrack.server.cluster`): it only stores and acknowledges.
        self.tracking = True
        #: ``fence(conn)``, passed to every derived write (the cluster's lease check).
        self.fence: Any = None
        #: In a cluster, the newest detection id this process has considered: batches
        #: other processes stored come after it (:meth:`catch_up`). None: one process.
        self.tail_after: int | None = None

    # ------------------------------------------------------------- components
    @property
    def tracker(self) -> Any:
        """The online tracker (:func:`demtrack.core.tracking.build_tracker`)."""
        return self.feed.tracker

    @property
    def n_buffered(self) -> int:
        """Fixes waiting in the reorder buffer."""
        return len(self.buffer)

    @property
    def keep_ended_s(self) -> float:
        """How long (s) ended tracks stay in memory: the setting, or the events' window."""
        window = self.event_params.window_s if self.event_params is not None else 0.0
        return max(self.retain_ended_s, window)

    # Internal state the tests and benchmarks read, kept where it always was.
    @property
    def _lock(self) -> Any:
        return self.commits.lock

    @property
    def _waiting(self) -> list[Request]:
        return self.commits.waiting

    @property
    def _queued_fixes(self) -> dict[int, Fix]:
        return self.buffer.fixes

    @property
    def _points(self) -> dict[int, tuple[np.ndarray, list[dict[str, Any]], list[str]]]:
        return self.bodies.points

    @_points.setter
    def _points(self, value: dict[int, tuple[np.ndarray, list[dict[str, Any]], list[str]]]) -> None:
        self.bodies.points = value

    # ---------------------------------------------------------------- start-up
    def start(self) -> dict[str, int]:
        """Rebuild the tracker from the stored fixes and finish interrupted work.

        See :meth:`_start`.
        """
        with self._lock:
            return self._start()

    def follow(self) -> None:
        """Store and acknowledge batches from now on, without tracking them (a follower).

        Loads what the acknowledgements check (each sensor's newest time and count, the
        stored poses); :meth:`lead` starts tracking.
        """
        with self._lock:
            self.tracking = False
            self._load_ingest_state()

    def lead(self, fence: Any) -> dict[str, int]:
        """Start tracking from the durable state: the cluster's lease was acquired.

        The tracking state is rebuilt from scratch (:meth:`_start`), every derived write
        from now on carries ``fence``, and batches other processes store are taken up
        by id (:meth:`catch_up`). Returns :meth:`start`'s counts.
        """
        with self._lock:
            self.tracking = False
            self.writes.close()  # what it held is rebuilt from the durable state
            self.writes = self._held_writes()
            self._fresh_tracking()
            self.fence = fence
            self.tail_after = 0
            counts = self._start()
            self.tracking = True
            return counts

    def _held_writes(self) -> HeldWrites:
        """A new, empty queue of derived writes on :attr:`store`."""
        return HeldWrites(self.store, self._publish_now, self.commits.lock)

    def _fresh_tracking(self) -> None:
        """The tracker, its reorder buffer, track bodies, pose book and events, all new."""
        self.buffer = ReorderBuffer(self.reorder_lag_s)
        self.feed = TrackerFeed(build_tracker(self.method, roads=self.site.roads), self.buffer)
        self.bodies = TrackBodies(self.site.frame)
        self.live_events: LiveEvents | None = None
        #: Fixes stored with ``tracked: false`` (they sorted before what was tracked).
        self.n_late = 0
        #: Pose telemetry: checked samples, rolling series, deferred detections.
        self.pose_book = PoseBook(self.site)
        #: ``sensor_pose`` messages, rate-limited per sensor.
        self.announcer = PoseAnnouncer(self._pose_interval_s)

    def catch_up(self) -> int:
        """Track the batches other processes stored since :attr:`tail_after`, by id.

        Returns the number of detections processed. A no-op unless this process tracks
        in a cluster.
        """
        with self._lock:
            return self._catch_up(None)

    def _catch_up(self, below: int | None, counted: set[int] | frozenset[int] = frozenset()) -> int:
        """:meth:`catch_up` with the lock held.

        ``below``: only detection ids under it (the first id of the caller's own batch,
        processed next). ``counted``: ids already counted per sensor (this process's own).
        """
        n = 0
        while self.tracking and self.tail_after is not None:
            posed = self._catch_up_poses()
            rows = self.store.detections(self.tail_after, CATCH_UP_CHUNK, unprocessed=True)
            if below is not None:
                rows = [r for r in rows if r[0] < below]
            if not rows:
                if posed:  # poses alone: release what waited for them, announce them
                    self._process([], posed=posed)
                break
            self.tail_after = rows[-1][0]
            for i, d in rows:  # counted here as this process counts its own batches
                if i in counted:
                    continue
                self._last_t[d.sensor] = max(d.t_s, self._last_t.get(d.sensor, d.t_s))
                self._n_det[d.sensor] = self._n_det.get(d.sensor, 0) + 1
            self._process(rows, posed=posed)
            n += len(rows)
        return n

    def _catch_up_poses(self) -> set[str]:
        """Poses other processes stored, newer than this one holds, into the series.

        Read before the detections they may pose (a pose batch commits before the
        detections it covers are sent, as the replays and the heads do). Returns the
        sensors whose series moved.
        """
        moved: set[str] = set()
        for sensor in sorted(self.site.sensors):  # one range read on (sensor, t_s) each
            held = self.pose_book.newest.get(sensor)
            after = -math.inf if held is None else float(held.t_s)
            bodies = self.store.poses(sensor, None if held is None else after)
            samples = [sample_from_body(b) for b in bodies if float(b["t_s"]) > after]
            if samples:
                self.pose_book.extend(sensor, samples)
                moved.add(sensor)
                last = self.pose_book.last_t.get(sensor, -math.inf)
                self.pose_book.last_t[sensor] = max(last, float(samples[-1].t_s))
        return moved

    def _load_ingest_state(self) -> None:
        """Each sensor's newest detection time and count, and the stored poses."""
        self._last_t = self.store.last_times()
        self._n_det = self.store.sensor_counts()
        self.pose_book.load(self.store.recent_poses(WINDOW_S), self.store.pose_last_times())

    def _start(self) -> dict[str, int]:
        """Rebuild the tracker from the stored fixes and finish interrupted work (lock held).

        The stored ``tracked`` fixes are sorted by ``(t_s, sensor, detection_id)``; those at most
        ``reorder_lag_s`` behind the newest go to the tracker, the rest back into the
        reorder buffer. Detections stored but not yet processed (a crash between commit
        and tracking) are processed now, and the tracks table is rewritten.

        Returns counts: ``replayed`` fixes and ``processed`` detections.
        """
        # The poses first: the unprocessed detections below are geolocated with them.
        self._load_ingest_state()
        load_stored_fixes(self.store, self.buffer)
        dropped: set[int] = set()

        def drop() -> list[int]:
            ids = self._drop_ended()
            dropped.update(ids)
            return ids

        replayed = self.feed.release(drop)
        # Every track as the replay left it (the table may hold tracks of fixes whose
        # batch was cut short); its messages were already sent before the restart.
        # Tracks the replay forgot (ended long ago) keep their stored rows.
        rows, _ = self._track_changes(self.tracker.tracks(), force=True)
        self.store.write_derived(
            [], rows, [], replace_tracks=True, keep_track_ids=dropped, **self._fenced()
        )
        self.bodies.dirty_from.clear()
        if self.event_params is not None:
            known = self.store.activity(open_only=True) + self.store.latest_activity(
                EventKind.HANDOFF
            )
            self.live_events = LiveEvents(self.site, self.event_params, known)
            if math.isfinite(self.feed.released_t):
                self.live_events.last_eval_t = self.feed.released_t
        processed, after = 0, 0
        while True:  # by id: detections waiting for their pose stay unprocessed
            pending = self.store.detections(after, 5000, unprocessed=True)
            if not pending:
                break
            after = pending[-1][0]
            self._process(pending)
            processed += len(pending)
        if self.tail_after is not None:
            self.tail_after = after
        return {"replayed": replayed, "processed": processed}

    def _fenced(self) -> dict[str, Any]:
        """``write_derived``'s fence keyword, when this process writes under a lease."""
        return {} if self.fence is None else {"fence": self.fence}

    # ------------------------------------------------------------------ ingest
    def _validate(self, records: Sequence[Any]) -> tuple[list[Detection], dict[str, Any]]:
        """Check records with the detection-file rules (:mod:`.validate`).

        Their inline poses go to ``self._inline`` (per sensor) when it is a dict.
        """
        return validate_records(records, self._last_t, self.sizes, self._inline)

    def ingest(self, records: Sequence[Any], batch_key: str | None = None) -> dict[str, Any]:
        """Validate, store durably, then geolocate, track and publish one batch.

        Returns the acknowledgement (the batch is committed when this returns): counts
        ``accepted`` / ``skipped`` by reason, the first issues, the new detection ids.

        Group commit: batches that arrive while another is being handled (several
        cameras posting at once) wait together; the next one to get the lock commits all
        of them in one transaction (one WAL sync) and processes them as one, in arrival
        order - each keeps its own batch row, acknowledgement and ``ingest`` message.
        """
        return self.commits.submit(records, batch_key, self._ingest_group)

    def ingest_poses(
        self, sensor: str, samples: Sequence[Any] | ParsedPoses, batch_key: str | None = None
    ) -> dict[str, Any]:
        """Store one sensor's pose samples durably, as :meth:`ingest` stores detections.

        ``samples``: :class:`~demtrack.core.camera.pose_series.PoseSample` values, or the
        :class:`~.pose_values.ParsedPoses` of posted records. They share the group
        commit with detection batches; once committed they join the sensor's series,
        detections waiting for them are geolocated and a ``sensor_pose`` message goes out.
        """
        parsed = samples if isinstance(samples, ParsedPoses) else ParsedPoses.of(samples)
        return self.commits.submit(parsed, batch_key, self._ingest_group, sensor=sensor)

    def _accept(self, req: Request) -> tuple[Any, ...]:
        """Validate one request after the batches before it and count its detections.

        Returns its detections, its report and its pose rows.
        """
        book = self.pose_book
        if req.sensor is not None:
            kept, ack = book.check(req.sensor, req.records)
            req.samples = {req.sensor: kept} if kept else {}
            return [], {**ack, "kind": "poses", "sensor": req.sensor}, book.rows(req.sensor, kept)
        inline: dict[str, Any] = {}
        self._inline = inline  # _validate fills it (tests replace _validate itself)
        dets, ack = self._validate(req.records)
        for d in dets:
            self._last_t[d.sensor] = max(d.t_s, self._last_t.get(d.sensor, d.t_s))
            self._n_det[d.sensor] = self._n_det.get(d.sensor, 0) + 1
        req.samples, rows = {}, []
        for sensor, samples in sorted(inline.items()):
            kept, pose_ack = book.check(sensor, ParsedPoses.of(samples), quiet_duplicates=True)
            if kept:
                req.samples[sensor] = kept
                rows += book.rows(sensor, kept)
            if pose_ack["skipped"]:
                ack["pose_skipped"] = ack.get("pose_skipped", 0) + pose_ack["skipped"]
        if rows:
            ack["poses"] = len(rows)
        return dets, ack, rows

    def _commit(self, group: list[Request]) -> tuple[list[tuple[int, Detection]], list[Ack]] | None:
        """Commit ``group`` in one transaction (:func:`.group_commit.commit_group`).

        On failure nothing is stored, the per-sensor counters are as before and every
        request of ``group`` carries the error.
        """
        last_t, n_det = dict(self._last_t), dict(self._n_det)
        pose_t = dict(self.pose_book.last_t)
        out = commit_group(self.store, group, self._accept)
        if out is None:
            self._last_t, self._n_det = last_t, n_det
            self.pose_book.last_t = pose_t
            return None
        self.n_commits += 1
        self.n_batches += len(group)
        return out

    def _ingest_group(self, group: list[Request]) -> None:
        """Commit ``group``'s batches in one transaction, then process them (lock held).

        If the shared transaction fails, each batch is committed again on its own, in
        order: one client's bad batch never fails another client's good one. A store that
        cannot write (full disk, lost file) fails them all at once.
        """
        out = self._commit(group)
        if out is None and len(group) > 1:
            err = next(r.error for r in group if r.error is not None)
            if not isinstance(err, StoreUnavailableError):
                pending: list[tuple[int, Detection]] = []
                acks: list[Ack] = []
                for req in group:
                    req.error = None
                    one = self._commit([req])
                    if one is not None:
                        pending += one[0]
                        acks += one[1]
                out = pending, acks
        if out is None:
            self._log_refused(group)
            return
        pending, acks = out
        self._log_refused([r for r in group if r.error is not None])
        if not acks:
            return
        posed = self._take_poses(group)
        if not self.tracking:  # a follower: stored and acknowledged; the leader tracks it
            return
        acks = [a for a in acks if a[0].get("kind") != "poses"]
        try:
            if self.tail_after is not None and pending:  # others' stored before, first
                if pending[-1][0] - pending[0][0] + 1 != len(pending):
                    # committed one by one (a batch failed the shared transaction): other
                    # processes' batches may lie between; all of them in id order, from
                    # the store (this group's ingest messages are not sent)
                    self._catch_up(None, counted={i for i, _ in pending})
                    return
                self._catch_up(below=pending[0][0])
                self.tail_after = max(self.tail_after, pending[-1][0])
            self._process(pending, acks=acks, posed=posed)
        except StoreUnavailableError as exc:  # durable batches; start-up replays them
            log.error("processing after commit stopped: %s", exc)
        except Exception:  # the batches are durable; start-up replays what failed here
            ids = ", ".join(str(a["batch_id"]) for a, _ in acks)
            log.exception("processing batch(es) %s failed after commit", ids)

    @staticmethod
    def _log_refused(group: Sequence[Request]) -> None:
        """One line per batch refused: a store that cannot write is not a traceback."""
        for req in group:
            if isinstance(req.error, StoreUnavailableError):
                log.error("ingest batch refused: %s", req.error)
            elif req.error is not None:
                log.error("ingest batch failed: %r", req.error, exc_info=req.error)

    # ------------------------------------------------------------------- poses
    def _take_poses(self, group: Sequence[Request]) -> set[str]:
        """Add the committed batches' pose samples to the series; the sensors they moved."""
        moved: set[str] = set()
        for req in group:
            if req.error is not None or req.ack is None or req.ack.get("duplicate"):
                continue
            for sensor, samples in (req.samples or {}).items():
                self.pose_book.extend(sensor, samples)
                moved.add(sensor)
        return moved

    def _arm_pose_flush(self) -> None:
        """Start a timer for the ``sensor_pose`` messages the rate limit held back."""
        delay = self.announcer.next_flush_s()
        if (
            delay is None
            or self._closed
            or (self._flush_timer is not None and self._flush_timer.is_alive())
        ):
            return
        self._flush_timer = threading.Timer(delay + 1e-3, self.flush_poses)
        self._flush_timer.daemon = True
        self._flush_timer.start()

    def flush_poses(self) -> None:
        """Send the held-back ``sensor_pose`` messages whose interval has passed."""
        try:
            with self._lock:
                self._flush_timer = None
                if self._closed:
                    return
                events = self.announcer.flush(self.pose_book.newest)
                if events:
                    self.writes.write([], [], events, [], fence=self.fence)
                self._arm_pose_flush()
        except Exception:  # noqa: BLE001 - a timer thread: log, never raise
            log.exception("sending held-back sensor_pose messages failed")

    def _publish_now(self, messages: list[Any]) -> None:
        """Hand ``messages`` to :attr:`publish` as it is now (it may be replaced)."""
        self.publish(messages)

    def close(self) -> None:
        """Stop the pose flush timer (before the store closes)."""
        with self._lock:
            self._closed = True
            self.writes.close()
            if self._flush_timer is not None:
                self._flush_timer.cancel()
                self._flush_timer = None

    # -------------------------------------------------------------- processing
    def _drop_ended(self) -> list[int]:
        """Forget tracks that ended more than :attr:`keep_ended_s` ago; their ids."""
        ids = self.feed.drop_ended(self.keep_ended_s)
        self.bodies.forget(ids)
        return ids

    def _fix_bodies(
        self, pending: list[tuple[int, Detection]], fixes: list[Fix]
    ) -> tuple[list[dict[str, Any] | None], list[Geodetic]]:
        """The stored bodies of ``pending``'s fixes (:func:`.fix_codec.fix_bodies`).

        The tracker's fix of each body, the one the start-up replay makes of it
        (:func:`.fix_codec.tracker_fixes`), waits in the reorder buffer's
        :attr:`~.ReorderBuffer.fixes`.
        """
        bodies, unfilled = fix_bodies(pending, fixes)
        self.buffer.fixes.update(tracker_fixes(bodies, fixes))
        return bodies, unfilled

    def _process(
        self,
        pending: list[tuple[int, Detection]],
        *,
        acks: Sequence[Ack] = (),
        posed: set[str] | frozenset[str] = frozenset(),
    ) -> None:
        """Geolocate, track, detect events, store and publish ``pending`` detections.

        ``acks``: each ingested batch's acknowledgement and newest detection time, for
        its ``ingest`` message. ``posed``: sensors whose poses just changed (their
        ``sensor_pose`` messages go with this batch's). Telemetry detections whose pose
        is not settled wait (:meth:`.PoseBook.split`); those that waited and now are
        settled or due join ``pending``.
        """
        horizon = max(self._last_t.values(), default=-math.inf) - self.reorder_lag_s
        batch_sensors = sorted({d.sensor for _, d in pending})
        pending = self.pose_book.split(pending, horizon)
        if not pending and not acks:  # poses alone, no detection due: nothing to track
            moved = self.announcer.due(posed, self.pose_book.newest)
            if moved:
                self.writes.write([], [], moved, [], fence=self.fence)
            self._arm_pose_flush()
            return
        dets = [d for _, d in pending]
        # The bodies' geodetic fields are filled by the track points' conversion below:
        # one pyproj round trip per batch, not two.
        bodies, unfilled, no_pose = geolocate_posed(
            self.site, self.pose_book, pending, self._fix_bodies
        )
        fixed = {det_id for (det_id, _), body in zip(pending, bodies, strict=True) if body}
        rows: list[FixRow] = []
        events: list[tuple[str, StreamPayload]] = list(
            self.announcer.due(posed, self.pose_book.newest)
        )
        n_no_pose: dict[int, int] = {}
        for (det_id, d), body, np_ in zip(pending, bodies, no_pose.tolist(), strict=True):
            if body is None:
                status = "no_pose" if np_ else "no_fix"
                body = {"detection_id": det_id, "hits": None, "tracked": False}
                if np_:
                    body["reason"] = "no_pose"
                    self.pose_book.n_no_pose += 1
                    n_no_pose[det_id] = 1
                rows.append((det_id, d.t_s, d.sensor, d.cls, status, body))
                continue
            if not self.buffer.admit((body["t_s"], body["sensor"], det_id)):
                body["tracked"] = False
                self.n_late += 1
            rows.append((det_id, d.t_s, d.sensor, d.cls, "fix", body))
            events.append(("fix", FixPayload(body)))
        released_before = self.feed.released_t
        self.feed.release()
        live_now = self.tracker.tracks(include_ended=False)
        live_ids = {t.id for t in live_now}
        changed = self._ended_since(released_before, live_ids) + live_now
        track_rows, track_events = self._track_changes(
            changed, live_ids=live_ids, also_geodetic=unfilled
        )
        events += track_events
        activity = [p.event for _, p in track_events if isinstance(p, EventPayload)]
        released_t = self.feed.released_t
        if self.live_events is not None and math.isfinite(released_t):
            if self._events_due(released_t):
                window = released_t - self.live_events.params.window_s
                found = self.live_events.evaluate(
                    self._window_tracks(window), self.bodies.live_ids, released_t
                )
                for body, news in found:  # stored; streamed when news (LiveEvents.evaluate)
                    activity.append(body)
                    if news:
                        events.append(("event", event_message(body)))
        events += sensor_status_messages(
            sorted({*batch_sensors, *(d.sensor for d in dets)}), self._last_t, self._n_det
        )
        for ack, t in acks:
            n_fixes = sum(1 for i in ack["detection_ids"] if i in fixed)
            if n_no_pose:
                ack["no_pose"] = sum(1 for i in ack["detection_ids"] if i in n_no_pose)
            events.append(("event", ingest_message(ack, n_fixes, t)))
        self.writes.write(
            rows,
            track_rows,
            events,
            activity,
            self.bodies.stored,
            fence=self.fence,
        )
        self._drop_ended()  # after their final rows are stored
        self._arm_pose_flush()

    def _ended_since(self, released_before: float, live_ids: set[int]) -> list[Track]:
        """Ended tracks this release may have changed: live at the last batch, or new.

        A track can be confirmed and end within one release (a batch holding its whole
        life, or an ended track taken up again and ended again): it was never live at a
        batch's end, yet a restart's replay stores it, so it is stored and sent now too.
        Every fix the tracker processed in this release is at most ``step_window_s`` older
        than the newest one released before it (older ones were processed then), so such
        a track's newest point is after that.
        """
        ended_ids = self.bodies.live_ids - live_ids
        horizon = released_before - float(getattr(self.tracker.config, "step_window_s", 0.0))
        if ended_ids:  # rare: read the ended tracks' final form once
            horizon = min(horizon, self.bodies.sent_since(ended_ids))
        # unchanged ones among them are skipped by ``TrackBodies.changes`` (same signature)
        return [t for t in self.tracker.tracks(ended_after_s=horizon) if t.id not in live_ids]

    def _events_due(self, released_t: float) -> bool:
        """Whether the live events run now: once per ``every_s`` cell of scenario time.

        The first batch whose released time enters a new cell of ``every_s`` (counted from
        0) runs them. A restart knows where that schedule stands from the replayed
        released time alone (the last run was in its cell), so it evaluates at the very
        batches an uninterrupted run does; a schedule counted from the last run's time
        (``LiveEvents.due``) drifted after a restart, and its events with it.
        """
        events = self.live_events
        if events is None:
            return False
        last = events.last_eval_t
        if last is None:
            return True
        every = events.params.every_s
        if every <= 0:
            return True
        return math.floor(released_t / every) > math.floor(last / every)

    def _window_tracks(self, t_from: float) -> list[Track]:
        """Tracks with a point at or after ``t_from`` (live ones and recently ended)."""
        tracks = self.tracker.tracks(ended_after_s=t_from)
        return [t for t in tracks if t.points and t.points[-1].t_s >= t_from]

    # ------------------------------------------------------------------ tracks
    def _refresh_points(
        self, tracks: Sequence[Track], also_geodetic: Sequence[Geodetic] = ()
    ) -> None:
        """Bring the cached JSON points of ``tracks`` up to date (:meth:`.TrackBodies.refresh`)."""
        self.bodies.refresh(tracks, also_geodetic)

    def track_body(self, track: Track, live: bool, first_index: int = 0) -> dict[str, Any]:
        """JSON body of a track, points from ``first_index`` on."""
        return self.bodies.body(track, live, first_index)

    def _track_changes(
        self,
        tracks: Sequence[Track],
        force: bool = False,
        live_ids: set[int] | None = None,
        also_geodetic: Sequence[Geodetic] = (),
    ) -> tuple[list[dict[str, Any]], list[tuple[str, StreamPayload]]]:
        """Of ``tracks``, those that changed since the last call: table rows and messages."""
        if live_ids is None:
            live_ids = {t.id for t in self.tracker.tracks(include_ended=False)}
        lag = int(getattr(self.tracker.config, "smoothing_lag", 0))
        return self.bodies.changes(
            tracks, live_ids, lag, self.track_body, force=force, also_geodetic=also_geodetic
        )
