"""Ingest -> durable store -> fixes -> online tracker -> stream messages.

One :class:`Pipeline` per server, called from worker threads; a lock serialises batches
so detection ids, the tracker's input order and the stream's sequence numbers all follow
arrival order. Batches that arrive while the lock is held are committed together (one
transaction, one WAL sync) and processed as one by whichever of them gets the lock next:
group commit, so several cameras posting at once share the fixed costs of a batch.
The tracker's input is always the fix *as stored* (rebuilt from its JSON),
so replaying the stored fixes at start-up rebuilds exactly the tracker state the live
run had: tracks after a restart are those the uninterrupted run would have made.

Reorder buffer
    Fixes wait in a heap until the newest accepted fix is ``reorder_lag_s`` ahead of them
    (scenario time), then go to the tracker in ``(t_s, sensor, detection_id)`` order, so
    batches from several cameras that arrive slightly out of order are tracked in time
    order, and in the same order whatever the arrival order. A fix that sorts before the
    last one handed to the tracker is stored with ``tracked: false``. Every fix handed
    over is then in that order overall, so the start-up replay sorts the stored
    ``tracked`` fixes, hands over those at most ``reorder_lag_s`` behind the newest and
    puts the rest back in the buffer: the same state as before the restart.

Memory
    The tracker forgets tracks that ended more than ``retain_ended_s`` ago (scenario
    time; never less than the re-acquisition window nor, with live events, their
    window), after their final form is stored: memory stays bounded over a long run
    while SQLite and the API keep every track. The start-up replay forgets them as it
    goes, and leaves their stored rows alone.

Live events
    After each batch :class:`~demtrack.server.live_events.LiveEvents` may run the activity
    detectors and hand-off prediction (every ``every_s`` of scenario time); its events are
    stored in the ``activity`` table and streamed as ``event`` messages.
"""

from __future__ import annotations

import heapq
import logging
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from demtrack.core.activity.detectors import ConvoyParams, LoiterParams, RendezvousParams
from demtrack.core.errors import DemtrackError
from demtrack.core.geolocation.fix_builder import build_fixes, sensor_sizes
from demtrack.core.io.detections import read_detection_records
from demtrack.core.site.folder import Site
from demtrack.core.site.zone_io import read_zones_geojson
from demtrack.core.tracking import build_tracker
from demtrack.core.tracking.types import CLASSES, Detection, Fix, Track

from .db import Store, dumps_json, published_text
from .hub import StreamMessage
from .live_events import LiveEventParams, LiveEvents

__all__ = ["Pipeline", "fix_from_body", "pipeline_options"]

log = logging.getLogger("demtrack.server")

#: ``publish(messages)``: each message a dict with ``seq`` (called under the lock, in order).
Publisher = Callable[[list[dict[str, Any]]], None]
_MAX_ISSUES = 20
#: The start-up replay forgets old ended tracks every this many fixes.
_REPLAY_DROP_EVERY = 4096


def _hit(p: list[float], sigma: float, cov: list[list[float]] | None = None) -> dict[str, Any]:
    """A stored hit; its geodetic fields (None here, in their places) are filled later."""
    hit: dict[str, Any] = {
        "e_m": p[0],
        "n_m": p[1],
        "u_m": p[2],
        "lat_deg": None,
        "lon_deg": None,
        "h_m": None,
        "sigma_m": sigma,
    }
    if cov is not None:
        hit["cov_en_m2"] = cov
    return hit


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
    }


def fix_from_body(body: dict[str, Any]) -> Fix:
    """The tracker's :class:`Fix` from a stored fix body (``detection_index`` = detection id).

    The same fix the public constructor makes (the direction normalised the same way),
    built without its per-field checks when one vectorised check shows the body is
    well formed - every stored body is, since the server wrote it; anything else goes
    through the constructor, which names the problem.
    """
    hits = body["hits"]
    road = body.get("road_hit")
    hits_enu = [[h["e_m"], h["n_m"], h["u_m"]] for h in hits]
    sigma = [h["sigma_m"] for h in hits]
    road_enu = None if road is None else [road["e_m"], road["n_m"], road["u_m"]]
    covs = [h.get("cov_en_m2") for h in hits]
    # bodies stored before covariances were kept have none: the tracker uses sigma_m
    cov = covs if covs and all(c is not None for c in covs) else None
    fast = _trusted_fix(body, hits_enu, sigma, road_enu, cov)
    if fast is not None:
        return fast
    return Fix(
        t_s=body["t_s"],
        sensor=body["sensor"],
        cls=body["cls"],
        detection_index=body["detection_id"],
        origin_enu=body["origin_enu"],
        direction_enu=body["direction_enu"],
        hits_enu=hits_enu,
        hit_sigma_m=sigma,
        road_hit_enu=road_enu,
        score=body.get("score"),
        hit_cov_en_m2=cov,
    )


def _stored_fix(det_id: int, d: Detection, fix: Fix) -> Fix:
    """What :func:`fix_from_body` makes of the body :meth:`Pipeline._fix_bodies` stores.

    The body holds the fix's own floats (``tolist`` and JSON keep every bit); the
    direction is normalised again, as the constructor does.
    """
    direction = np.array(fix.direction_enu, dtype=np.float64)
    # np.linalg.norm of a 1-D float array is sqrt(x.dot(x)): the same bits, one call
    direction /= math.sqrt(direction.dot(direction))
    direction.setflags(write=False)
    return Fix._trusted(
        d.t_s,
        d.sensor,
        d.cls,
        det_id,
        fix.origin_enu,
        direction,
        fix.hits_enu,
        fix.hit_sigma_m,
        fix.road_hit_enu,
        d.score,
        fix.hit_cov_en_m2,
    )


def _trusted_fix(
    body: dict[str, Any],
    hits_enu: list[list[float]],
    sigma: list[float],
    road_enu: list[float] | None,
    cov: list[Any] | None = None,
) -> Fix | None:
    """:func:`fix_from_body`'s fix without per-field checks, or None if anything is off."""
    try:
        t_s = float(body["t_s"])
        score = body.get("score")
        flat = np.array(
            [
                t_s,
                *body["origin_enu"],
                *body["direction_enu"],
                *(road_enu or ()),
                *sigma,
                *(v for h in hits_enu for v in h),
                *(v for c in cov or () for row in c for v in row),
                0.0 if score is None else float(score),
            ],
            dtype=np.float64,
        )
    except (TypeError, ValueError):
        return None
    n = len(sigma)
    n_road = 0 if road_enu is None else 3
    n_cov = 0 if cov is None else 4 * n
    if (
        flat.shape != (8 + n_road + 4 * n + n_cov,)
        or any(len(h) != 3 for h in hits_enu)
        or (cov is not None and any(len(c) != 2 or any(len(r) != 2 for r in c) for c in cov))
        or body.get("cls") not in CLASSES
        or not isinstance(body.get("sensor"), str)
        or not np.isfinite(flat).all()
    ):
        return None
    origin = flat[1:4].copy()
    direction = flat[4:7].copy()
    norm = float(np.linalg.norm(direction))
    road = flat[7 : 7 + n_road].copy() if road_enu is not None else None
    sig = flat[7 + n_road : 7 + n_road + n].copy()
    hits = flat[7 + n_road + n : 7 + n_road + 4 * n].reshape(n, 3).copy()
    covs = None
    if cov is not None:
        covs = flat[7 + n_road + 4 * n : 7 + n_road + 4 * n + n_cov].reshape(n, 2, 2).copy()
        det = covs[:, 0, 0] * covs[:, 1, 1] - covs[:, 0, 1] * covs[:, 1, 0]
        if np.any(covs[:, 0, 1] != covs[:, 1, 0]) or np.any(covs[:, 0, 0] <= 0) or np.any(det <= 0):
            return None  # the constructor symmetrises or refuses: let it
    if norm == 0.0 or np.any(sig <= 0):
        return None
    direction /= norm
    for a in (origin, direction, road, sig, hits, covs):
        if a is not None:
            a.setflags(write=False)
    return Fix._trusted(
        t_s,
        body["sensor"],
        body["cls"],
        int(body["detection_id"]),
        origin,
        direction,
        hits,
        sig,
        road,
        None if score is None else score,
        covs,
    )


@dataclass(eq=False)
class _Request:
    """One :meth:`Pipeline.ingest` call waiting for its group's commit."""

    records: Sequence[Any]
    batch_key: str | None
    ack: dict[str, Any] | None = None
    error: BaseException | None = None


class Pipeline:
    """The server's ingest and tracking state.

    Parameters
    ----------
    site : Site
    store : Store
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
    """

    def __init__(
        self,
        site: Site,
        store: Store,
        method: str,
        publish: Publisher,
        *,
        reorder_lag_s: float = 0.5,
        events: LiveEventParams | None = None,
        zones_path: Any = None,
        retain_ended_s: float = 600.0,
    ) -> None:
        self.site = site
        self.store = store
        self.method = method
        self.publish = publish
        self.sizes = sensor_sizes(site)
        self.tracker = build_tracker(method, roads=site.roads)
        self.reorder_lag_s = float(reorder_lag_s)
        self.retain_ended_s = float(retain_ended_s)
        if events is not None and zones_path is not None:
            from pathlib import Path

            if Path(zones_path).is_file():
                zones = tuple(read_zones_geojson(zones_path, site.frame))
                events = LiveEventParams(**{**events.__dict__, "zones": zones})
        self.event_params = events
        self.live_events: LiveEvents | None = None
        self._lock = threading.Lock()
        self._waiting_lock = threading.Lock()
        self._waiting: list[_Request] = []
        #: Ingest transactions committed and the batches they held (group commit).
        self.n_commits = 0
        self.n_batches = 0
        self._last_t: dict[str, float] = {}
        self._n_det: dict[str, int] = {}
        self._seen: dict[int, tuple[int, bytes, bool]] = {}
        self._live_ids: set[int] = set()
        # Per track: positions as last sent, their JSON point dicts and those dicts encoded
        # (a changed track's stored body is re-assembled from the encoded points).
        self._points: dict[int, tuple[np.ndarray, list[dict[str, Any]], list[str]]] = {}
        # Per track: the first point index whose encoding changed since its row was last
        # stored (the store rewrites points from there on); cleared once a write commits.
        self._dirty_from: dict[int, int] = {}
        self._heap: list[tuple[float, str, int, dict[str, Any]]] = []
        #: Tracker fixes of the queued bodies made in this run (detection id -> fix):
        #: what :func:`fix_from_body` would make of the body, without the round trip.
        self._queued_fixes: dict[int, Fix] = {}
        self._newest_t = -math.inf
        self._released_t = -math.inf
        self._released_key: tuple[float, str, int] = (-math.inf, "", -1)
        self.n_late = 0

    # ---------------------------------------------------------------- start-up
    def start(self) -> dict[str, int]:
        """Rebuild the tracker from the stored fixes and finish interrupted work.

        The stored ``tracked`` fixes are sorted by ``(t_s, sensor, detection_id)``; those at most
        ``reorder_lag_s`` behind the newest go to the tracker, the rest back into the
        reorder buffer. Detections stored but not yet processed (a crash between commit
        and tracking) are processed now, and the tracks table is rewritten.

        Returns counts: ``replayed`` fixes and ``processed`` detections.
        """
        with self._lock:
            self._last_t = self.store.last_times()
            self._n_det = self.store.sensor_counts()
            queued: list[tuple[float, str, int, dict[str, Any]]] = []
            after = 0
            while True:
                bodies = self.store.fixes(after, 5000)
                if not bodies:
                    break
                for body in bodies:
                    after = body["detection_id"]
                    if body.get("hits") is not None and body.get("tracked"):
                        queued.append((body["t_s"], body["sensor"], body["detection_id"], body))
            queued.sort(key=lambda q: q[:3])
            self._heap = queued  # a sorted list is a heap
            if queued:
                self._newest_t = max(q[0] for q in queued)
            dropped: set[int] = set()
            replayed = self._release(dropped)
            # Every track as the replay left it (the table may hold tracks of fixes whose
            # batch was cut short); its messages were already sent before the restart.
            # Tracks the replay forgot (ended long ago) keep their stored rows.
            rows, _ = self._track_changes(self.tracker.tracks(), force=True)
            self.store.write_derived([], rows, [], replace_tracks=True, keep_track_ids=dropped)
            self._dirty_from.clear()
            if self.event_params is not None:
                known = self.store.activity(open_only=True) + self.store.latest_activity("handoff")
                self.live_events = LiveEvents(self.site, self.event_params, known)
                if math.isfinite(self._released_t):
                    self.live_events.last_eval_t = self._released_t
            processed = 0
            while True:
                pending = self.store.detections(0, 5000, unprocessed=True)
                if not pending:
                    break
                self._process(pending)
                processed += len(pending)
            return {"replayed": replayed, "processed": processed}

    # ------------------------------------------------------------------ ingest
    def _validate(self, records: Sequence[Any]) -> tuple[list[Detection], dict[str, Any]]:
        """Check records with the detection-file rules (:mod:`demtrack.core.io.detections`).

        Time order is checked across batches too: one valid seed record per sensor at its
        latest stored time goes first, so the reader's own ``time_backwards`` rule sees it.
        Only the batch's own sensors need one (the reader keeps its time order per sensor,
        and a seed is never skipped), so a camera's small batch checks no others' seeds.
        """
        named = {
            r["sensor"] for r in records if isinstance(r, dict) and isinstance(r.get("sensor"), str)
        }
        seeds = [
            {"t": t, "sensor": s, "bbox": [0, 0, 0, 0], "class": "human"}
            for s, t in sorted(self._last_t.items())
            if s in named and s in self.sizes
        ]
        dets, report = read_detection_records(
            [*seeds, *records], sensors=self.sizes, max_examples=_MAX_ISSUES
        )
        n_seed = len(seeds)
        if len(dets) < n_seed or report.n_records != n_seed + len(records):
            raise RuntimeError("internal: detection seed records were not accepted")
        issues = [
            {"index": e.line - 1 - n_seed, "reason": e.reason, "message": e.message}
            for e in report.examples
        ]
        ack = {
            "n_records": len(records),
            "accepted": len(dets) - n_seed,
            "skipped": report.n_skipped,
            "counts": dict(report.counts),
            "issues": issues,
        }
        return dets[n_seed:], ack

    def ingest(self, records: Sequence[Any], batch_key: str | None = None) -> dict[str, Any]:
        """Validate, store durably, then geolocate, track and publish one batch.

        Returns the acknowledgement (the batch is committed when this returns): counts
        ``accepted`` / ``skipped`` by reason, the first issues, the new detection ids.

        Group commit: batches that arrive while another is being handled (several
        cameras posting at once) wait together; the next one to get the lock commits all
        of them in one transaction (one WAL sync) and processes them as one, in arrival
        order - each keeps its own batch row, acknowledgement and ``ingest`` message.
        """
        req = _Request(records, batch_key)
        with self._waiting_lock:
            self._waiting.append(req)
        with self._lock:
            if req.ack is None and req.error is None:
                with self._waiting_lock:
                    group, self._waiting = self._waiting, []
                self._ingest_group(group)
        if req.error is not None:
            raise req.error
        assert req.ack is not None
        return req.ack

    def _ingest_group(self, group: list[_Request]) -> None:
        """Commit ``group``'s batches in one transaction, then process them (lock held)."""
        last_t, n_det = dict(self._last_t), dict(self._n_det)
        made: dict[int, tuple[list[Detection], dict[str, Any]]] = {}

        def maker(k: int, req: _Request) -> Callable[[], tuple[list[Detection], dict[str, Any]]]:
            def make() -> tuple[list[Detection], dict[str, Any]]:
                dets, ack = self._validate(req.records)  # after the batches before it
                for d in dets:
                    self._last_t[d.sensor] = max(d.t_s, self._last_t.get(d.sensor, d.t_s))
                    self._n_det[d.sensor] = self._n_det.get(d.sensor, 0) + 1
                made[k] = (dets, ack)
                return dets, ack

            return make

        try:
            stored = self.store.insert_batches(
                [(maker(k, req), req.batch_key) for k, req in enumerate(group)]
            )
        except BaseException as exc:  # nothing committed: every batch of the group fails
            self._last_t, self._n_det = last_t, n_det
            for req in group:
                req.error = exc
            return
        self.n_commits += 1
        self.n_batches += len(group)
        pending: list[tuple[int, Detection]] = []
        acks: list[tuple[dict[str, Any], float | None]] = []
        for k, (req, sb) in enumerate(zip(group, stored, strict=True)):
            req.ack = {
                **sb.report,
                "batch_id": sb.batch_id,
                "detection_ids": list(sb.detection_ids),
                "duplicate": sb.duplicate,
            }
            if sb.duplicate:
                continue
            dets = made[k][0]
            pending += zip(sb.detection_ids, dets, strict=True)
            acks.append((req.ack, max((d.t_s for d in dets), default=None)))
        if not acks:
            return
        try:
            self._process(pending, acks=acks)
        except Exception:  # the batches are durable; start-up replays what failed here
            ids = ", ".join(str(a["batch_id"]) for a, _ in acks)
            log.exception("processing batch(es) %s failed after commit", ids)

    # ------------------------------------------------------------ reorder buffer
    def _admit(self, body: dict[str, Any]) -> bool:
        """Queue a fix for the tracker; False when it sorts before what was tracked."""
        key = (body["t_s"], body["sensor"], body["detection_id"])
        if key < self._released_key:
            return False
        heapq.heappush(self._heap, (*key, body))
        self._newest_t = max(self._newest_t, body["t_s"])
        return True

    def _release(self, dropped: set[int] | None = None) -> int:
        """Hand the fixes at most ``reorder_lag_s`` behind the newest to the tracker.

        ``dropped``: forget old ended tracks every few thousand fixes on the way (the
        start-up replay, whose tracks are already stored) and add their ids to it.
        """
        horizon = self._newest_t - self.reorder_lag_s
        n = 0
        while self._heap and self._heap[0][0] <= horizon:
            if dropped is not None and n % _REPLAY_DROP_EVERY == _REPLAY_DROP_EVERY - 1:
                dropped.update(self._drop_ended())
            t, sensor, det_id, body = heapq.heappop(self._heap)
            self._released_key = (t, sensor, det_id)
            fix = self._queued_fixes.pop(det_id, None)
            try:
                self.tracker.update(fix or fix_from_body(body), index=det_id)
            except DemtrackError:  # cannot happen in time order; never stop the stream
                log.exception("tracker refused fix %s", det_id)
            self._released_t = max(self._released_t, t)
            n += 1
        if dropped is not None:
            dropped.update(self._drop_ended())
        return n

    @property
    def keep_ended_s(self) -> float:
        """How long (s) ended tracks stay in memory: the setting, or the events' window."""
        window = self.event_params.window_s if self.event_params is not None else 0.0
        return max(self.retain_ended_s, window)

    def _drop_ended(self) -> list[int]:
        """Forget tracks that ended more than :attr:`keep_ended_s` ago; their ids."""
        if not math.isfinite(self._released_t):
            return []
        ids = self.tracker.drop_ended(self._released_t - self.keep_ended_s)
        for i in ids:
            self._seen.pop(i, None)
            self._points.pop(i, None)
            self._dirty_from.pop(i, None)
        return ids

    @property
    def n_buffered(self) -> int:
        """Fixes waiting in the reorder buffer."""
        return len(self._heap)

    # -------------------------------------------------------------- processing
    def _process(
        self,
        pending: list[tuple[int, Detection]],
        *,
        acks: Sequence[tuple[dict[str, Any], float | None]] = (),
    ) -> None:
        """Geolocate, track, detect events, store and publish ``pending`` detections.

        ``acks``: each ingested batch's acknowledgement and newest detection time, for
        its ``ingest`` message.
        """
        dets = [d for _, d in pending]
        fixes, _ = build_fixes(self.site, dets)
        # The bodies' geodetic fields are filled by the track points' conversion below:
        # one pyproj round trip per batch, not two.
        bodies, unfilled = self._fix_bodies(pending, fixes)
        fixed = {det_id for (det_id, _), body in zip(pending, bodies, strict=True) if body}
        rows: list[tuple[int, float, str, str, str, dict[str, Any]]] = []
        events: list[tuple[str, dict[str, Any]]] = []
        for (det_id, d), body in zip(pending, bodies, strict=True):
            if body is None:
                body = {"detection_id": det_id, "hits": None, "tracked": False}
                rows.append((det_id, d.t_s, d.sensor, d.cls, "no_fix", body))
                continue
            if not self._admit(body):
                body["tracked"] = False
                self._queued_fixes.pop(det_id, None)
                self.n_late += 1
            rows.append((det_id, d.t_s, d.sensor, d.cls, "fix", body))
            events.append(("fix", {"type": "fix", "fix": body}))
        self._release()
        live_now = self.tracker.tracks(include_ended=False)
        live_ids = {t.id for t in live_now}
        ended_ids = self._live_ids - live_ids
        changed = live_now
        if ended_ids:  # rare: read the ended tracks' final form once
            recent = self.tracker.tracks(ended_after_s=self._sent_since(ended_ids))
            changed = [t for t in recent if t.id in ended_ids] + live_now
        track_rows, track_events = self._track_changes(
            changed, live_ids=live_ids, also_geodetic=unfilled
        )
        events += track_events
        activity = [p["event"] for kind, p in track_events if kind == "event"]
        if self.live_events is not None and math.isfinite(self._released_t):
            if self.live_events.due(self._released_t):
                window = self._released_t - self.live_events.params.window_s
                found = self.live_events.evaluate(
                    self._window_tracks(window), self._live_ids, self._released_t
                )
                for body in found:
                    activity.append(body)
                    if body["state"] != "update":
                        events.append(("event", _event_message(body)))
        sensors = sorted({d.sensor for d in dets})
        for s in sensors:
            events.append(
                (
                    "sensor_status",
                    {
                        "type": "sensor_status",
                        "sensor": s,
                        "last_t_s": self._last_t.get(s),
                        "n_detections": self._n_det.get(s, 0),
                    },
                )
            )
        for ack, t in acks:
            n_fixes = sum(1 for i in ack["detection_ids"] if i in fixed)
            text = (
                f"batch {ack['batch_id']}: {ack['accepted']} of {ack['n_records']} detections"
                f" accepted, {n_fixes} fixes"
            )
            events.append(("event", {"type": "event", "kind": "ingest", "t_s": t, "text": text}))
        stored = self.store.write_derived(rows, track_rows, events, activity=activity)
        for r in track_rows:  # stored: their points are clean
            self._dirty_from.pop(r["id"], None)
        self.publish(
            [
                StreamMessage(p, s, published_text(text, s))
                for (_, p), (s, text) in zip(events, stored, strict=True)
            ]
        )
        self._drop_ended()  # after their final rows are stored

    def _window_tracks(self, t_from: float) -> list[Track]:
        """Tracks with a point at or after ``t_from`` (live ones and recently ended)."""
        tracks = self.tracker.tracks(ended_after_s=t_from)
        return [t for t in tracks if t.points and t.points[-1].t_s >= t_from]

    def _sent_since(self, ids: set[int]) -> float:
        """The earliest newest-point time of the tracks ``ids`` as last sent (-inf if unknown).

        A track only gains points, so its final form ends at or after that time: reading
        the ended tracks from there on avoids rebuilding every track the session ever had.
        """
        ends = [
            self._points[i][1][-1]["t_s"] for i in ids if i in self._points and self._points[i][1]
        ]
        return min(ends) if len(ends) == len(ids) else -math.inf

    def _fix_bodies(
        self, pending: list[tuple[int, Detection]], fixes: list[Fix]
    ) -> tuple[list[dict[str, Any] | None], list[tuple[np.ndarray, list[dict[str, Any]]]]]:
        """The stored body of each detection's fix (None: no fix), geodetic fields unfilled.

        The hits' ``lat_deg``, ``lon_deg`` and ``h_m`` are left None (in their places);
        the second value, ``[(points (k, 3), hit dicts)]`` (empty when there is no hit), is
        for :meth:`_refresh_points` to fill them, before the bodies are used.
        """
        by_index = {f.detection_index: f for f in fixes}
        chunks = []
        for f in fixes:
            chunks.append(f.hits_enu)
            if f.road_hit_enu is not None:
                chunks.append(f.road_hit_enu[None, :])
        dicts: list[dict[str, Any]] = []
        out: list[dict[str, Any] | None] = []
        for i, (det_id, d) in enumerate(pending):
            fix = by_index.get(i)
            if fix is None:
                out.append(None)
                continue
            hits = []
            covs = [None] * fix.n_hits if fix.hit_cov_en_m2 is None else fix.hit_cov_en_m2.tolist()
            for p, sigma, cov in zip(
                fix.hits_enu.tolist(), fix.hit_sigma_m.tolist(), covs, strict=True
            ):
                hits.append(_hit(p, sigma, cov))
            dicts += hits
            road = None
            if fix.road_hit_enu is not None:
                sigma = float(np.min(fix.hit_sigma_m)) if len(fix.hit_sigma_m) else 1.0
                road = _hit(fix.road_hit_enu.tolist(), sigma)
                dicts.append(road)
            u0, _, u1, v1 = d.bbox
            self._queued_fixes[det_id] = _stored_fix(det_id, d, fix)
            out.append(
                {
                    "detection_id": det_id,
                    "t_s": d.t_s,
                    "sensor": d.sensor,
                    "cls": d.cls,
                    "score": d.score,
                    "bbox": list(d.bbox),
                    "foot_pixel": [0.5 * (u0 + u1), v1],
                    "origin_enu": fix.origin_enu.tolist(),
                    "direction_enu": fix.direction_enu.tolist(),
                    "hits": hits,
                    "road_hit": road,
                    "tracked": True,
                }
            )
        return out, [(np.vstack(chunks), dicts)] if chunks else []

    # ------------------------------------------------------------------ tracks
    def _refresh_points(
        self,
        tracks: Sequence[Track],
        also_geodetic: Sequence[tuple[np.ndarray, list[dict[str, Any]]]] = (),
    ) -> None:
        """Bring the cached JSON points of ``tracks`` up to date.

        Only points that changed since the last call are converted and encoded (a track
        changes at its end), and the new points of all ``tracks`` go through one geodetic
        conversion: per call, not per track (each costs a pyproj round trip).
        ``also_geodetic``: ``(points (k, 3), dicts)`` pairs whose dicts get the points'
        ``lat_deg``, ``lon_deg`` and ``h_m`` from that same conversion (the batch's fix
        hits; PROJ converts each point on its own, so the values are those of a call of
        their own).
        """
        todo = []
        for track in tracks:
            p = track.p_enu
            cached = self._points.get(track.id)
            if cached is not None and cached[0] is p:
                continue  # the same Track value as last time (its positions array is cached)
            same = 0
            if cached is not None:
                old_p, old_pts, old_js = cached
                m = min(len(old_p), len(p))
                diff = np.flatnonzero(np.any(old_p[:m] != p[:m], axis=1))
                same = int(diff[0]) if len(diff) else m
                same = min(same, len(old_pts))
                if same == len(p) == len(old_pts):
                    continue  # nothing changed
                pts, js = old_pts[:same], old_js[:same]
            else:
                pts, js = [], []
            todo.append((track, same, pts, js))
            self._dirty_from[track.id] = min(same, self._dirty_from.get(track.id, same))
        if not todo and not also_geodetic:
            return
        parts = [t.p_enu[same:] for t, same, _, _ in todo]
        n_track = sum(len(a) for a in parts)
        q = np.concatenate(parts + [a for a, _ in also_geodetic])
        lat, lon, h = (
            np.atleast_1d(a).tolist()
            for a in self.site.frame.to_geodetic(q[:, 0], q[:, 1], q[:, 2])
        )
        k = n_track
        for _, dicts in also_geodetic:
            for d in dicts:
                d["lat_deg"], d["lon_deg"], d["h_m"] = lat[k], lon[k], h[k]
                k += 1
        rows = q[:n_track].tolist()
        k = 0
        for track, same, pts, js in todo:
            for tp in track.points[same:]:
                e, n, u = rows[k]
                pts.append(
                    {
                        "t_s": tp.t_s,
                        "e_m": e,
                        "n_m": n,
                        "u_m": u,
                        "lat_deg": lat[k],
                        "lon_deg": lon[k],
                        "h_m": h[k],
                        "sensors": list(tp.sensors),
                        "detection_ids": list(tp.fix_indices),
                    }
                )
                js.append(dumps_json(pts[-1]))
                k += 1
            self._points[track.id] = (track.p_enu, pts, js)

    def _point_dicts(self, track: Track) -> list[dict[str, Any]]:
        """JSON points of a track; geodetic conversion only for points that changed."""
        self._refresh_points([track])
        return self._points[track.id][1]

    def track_body(self, track: Track, live: bool, first_index: int = 0) -> dict[str, Any]:
        """JSON body of a track, points from ``first_index`` on."""
        points = self._point_dicts(track)[first_index:]
        return {
            "id": track.id,
            "cls": track.cls,
            "sensors": sorted(track.sensors),
            "gaps": [list(g) for g in track.gaps],
            "live": live,
            "n_points": len(track.points),
            "first_index": first_index,
            "points": points,
        }

    def _track_changes(
        self,
        tracks: Sequence[Track],
        force: bool = False,
        live_ids: set[int] | None = None,
        also_geodetic: Sequence[tuple[np.ndarray, list[dict[str, Any]]]] = (),
    ) -> tuple[list[dict[str, Any]], list[tuple[str, dict[str, Any]]]]:
        """Of ``tracks``, those that changed since the last call: table rows and messages.

        ``live_ids``: the ids of the tracker's live tracks, when the caller has them.
        ``also_geodetic``: passed to :meth:`_refresh_points` (one conversion for both).
        """
        if live_ids is None:
            live_ids = {t.id for t in self.tracker.tracks(include_ended=False)}
        self._live_ids = live_ids
        lag = int(getattr(self.tracker.config, "smoothing_lag", 0))
        rows, events = [], []
        changed = []
        for track in tracks:
            if not track.points:
                continue
            live = track.id in live_ids
            p = track.p_enu
            sig = (len(track.points), p[-(lag + 1) :].tobytes(), live)
            prev = self._seen.get(track.id)
            if prev == sig and not force:
                continue
            self._seen[track.id] = sig
            changed.append((track, live, p, prev))
        self._refresh_points([t for t, _, _, _ in changed], also_geodetic)
        for track, live, p, prev in changed:
            full = self.track_body(track, live)
            start = 0 if force else self._dirty_from.get(track.id, len(track.points))
            rows.append(
                {
                    "id": track.id,
                    "cls": track.cls,
                    "t_start": track.points[0].t_s,
                    "t_end": track.points[-1].t_s,
                    "e_min": float(p[:, 0].min()),
                    "n_min": float(p[:, 1].min()),
                    "e_max": float(p[:, 0].max()),
                    "n_max": float(p[:, 1].max()),
                    "sensors": sorted(track.sensors),
                    "live": live,
                    "body": dumps_json({k: v for k, v in full.items() if k != "points"}),
                    "points_from": start,
                    "point_texts": self._points[track.id][2][start:],
                }
            )
            if not live:
                self._points.pop(track.id, None)  # ended: no more changes expected
            if force:
                continue
            first = 0 if prev is None else max(0, min(prev[0], len(track.points)) - lag - 1)
            tail = dict(full, first_index=first, points=full["points"][first:])
            events.append(("track_update", {"type": "track_update", "track": tail}))
            if prev is None:
                events.append(("event", self._track_event("track_confirmed", track)))
            elif prev[2] and not live:
                events.append(("event", self._track_event("track_ended", track)))
        return rows, events

    def _track_event(self, kind: str, track: Track) -> dict[str, Any]:
        last = track.points[-1]
        t, where = last.t_s, last.p_enu
        lat, lon, h = (float(v) for v in self.site.frame.to_geodetic(*where))
        body = {
            "key": f"{kind}:{track.id}",
            "identity": f"{kind}:{track.id}",
            "kind": kind,
            "state": "start",
            "t_start_s": t,
            "t_end_s": t,
            "track_ids": [track.id],
            "sensors": sorted(track.sensors),
            "p_enu": [float(v) for v in where],
            "lat_deg": lat,
            "lon_deg": lon,
            "h_m": h,
            "details": {"cls": track.cls, "n_points": len(track.points)},
            "open": False,
        }
        return _event_message(body)


_EVENT_TEXT = {
    "loitering": "track {ids} loitering",
    "rendezvous": "tracks {ids} rendezvous",
    "convoy": "tracks {ids} in convoy",
    "zone-enter": "track {ids} entered {zone}",
    "zone-leave": "track {ids} left {zone}",
    "handoff": "track {ids}: {current} loses it at {exit:.1f} s, next {next}",
    "track_confirmed": "track {ids} ({cls}) confirmed",
    "track_ended": "track {ids} ({cls}) ended",
}


def _event_message(body: dict[str, Any]) -> dict[str, Any]:
    """The ``event`` stream message of an activity body."""
    d = body.get("details", {})
    text = _EVENT_TEXT.get(body["kind"], body["kind"]).format(
        ids=", ".join(str(i) for i in body["track_ids"]),
        zone=d.get("zone", ""),
        current=d.get("current"),
        next=d.get("next_sensor"),
        exit=d.get("exit_t_s") or 0.0,
        cls=d.get("cls", ""),
    )
    if body["state"] == "end":
        text += f" (ended, {body['t_end_s'] - body['t_start_s']:.0f} s)"
    return {
        "type": "event",
        "kind": body["kind"],
        "t_s": body["t_end_s"] if body["state"] == "end" else body["t_start_s"],
        "text": text,
        "event": body,
    }
