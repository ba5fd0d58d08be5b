"""Ingest -> durable store -> fixes -> online tracker -> stream messages.

One :class:`Pipeline` per server, called from worker threads; a lock serialises batches
so detection ids, the tracker's input order and the stream's sequence numbers all follow
arrival order. The tracker's input is always the fix *as stored* (rebuilt from its JSON),
so replaying the stored fixes at start-up rebuilds exactly the tracker state the live
run had: tracks after a restart are those the uninterrupted run would have made.
"""

from __future__ import annotations

import io
import json
import logging
import threading
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from demtrack.core.detections import read_detections_jsonl
from demtrack.core.errors import DemtrackError
from demtrack.core.fix_builder import build_fixes, sensor_sizes
from demtrack.core.site import Site
from demtrack.core.tracking import build_tracker
from demtrack.core.tracking.types import Detection, Fix, Track

from .db import Store

__all__ = ["Pipeline", "fix_from_body"]

log = logging.getLogger("demtrack.server")

#: ``publish(messages)``: each message a dict with ``seq`` (called under the lock, in order).
Publisher = Callable[[list[dict[str, Any]]], None]
_MAX_ISSUES = 20


def _hit(p: np.ndarray, sigma: float, geo: tuple[float, float, float]) -> dict[str, float]:
    return {
        "e_m": float(p[0]),
        "n_m": float(p[1]),
        "u_m": float(p[2]),
        "lat_deg": geo[0],
        "lon_deg": geo[1],
        "h_m": geo[2],
        "sigma_m": float(sigma),
    }


def fix_from_body(body: dict[str, Any]) -> Fix:
    """The tracker's :class:`Fix` from a stored fix body (``detection_index`` = detection id)."""
    hits = body["hits"]
    road = body.get("road_hit")
    return Fix(
        t_s=body["t_s"],
        sensor=body["sensor"],
        cls=body["cls"],
        detection_index=body["detection_id"],
        origin_enu=body["origin_enu"],
        direction_enu=body["direction_enu"],
        hits_enu=[[h["e_m"], h["n_m"], h["u_m"]] for h in hits],
        hit_sigma_m=[h["sigma_m"] for h in hits],
        road_hit_enu=None if road is None else [road["e_m"], road["n_m"], road["u_m"]],
        score=body.get("score"),
    )


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
    """

    def __init__(self, site: Site, store: Store, method: str, publish: Publisher) -> None:
        self.site = site
        self.store = store
        self.method = method
        self.publish = publish
        self.sizes = sensor_sizes(site)
        self.tracker = build_tracker(method, roads=site.roads)
        self._lock = threading.Lock()
        self._last_t: dict[str, float] = {}
        self._n_det: dict[str, int] = {}
        self._seen: dict[int, tuple[int, bytes, bool]] = {}
        self.n_late = 0

    # ---------------------------------------------------------------- start-up
    def start(self) -> dict[str, int]:
        """Rebuild the tracker from the stored fixes and finish interrupted work.

        Detections stored but not yet processed (a crash between commit and tracking) are
        processed now, and the tracks table is rewritten.

        Returns counts: ``replayed`` fixes and ``processed`` detections.
        """
        with self._lock:
            self._last_t = self.store.last_times()
            self._n_det = self.store.sensor_counts()
            replayed, after = 0, 0
            while True:
                bodies = self.store.fixes(after, 5000)
                if not bodies:
                    break
                for body in bodies:
                    after = body["detection_id"]
                    if body.get("hits") is not None and body.get("tracked"):
                        self.tracker.update(fix_from_body(body), index=body["detection_id"])
                        replayed += 1
            # Every track as the replay left it (the table may hold tracks of fixes whose
            # batch was cut short); its messages were already sent before the restart.
            rows, _ = self._track_changes(force=True)
            self.store.write_derived([], rows, [], replace_tracks=True)
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
        """Check records with the detection-file rules (:mod:`demtrack.core.detections`).

        Time order is checked across batches too: one valid seed record per sensor at its
        latest stored time goes first, so the reader's own ``time_backwards`` rule sees it.
        """
        seeds = [
            {"t": t, "sensor": s, "bbox": [0, 0, 0, 0], "class": "human"}
            for s, t in sorted(self._last_t.items())
            if s in self.sizes
        ]
        text = "".join(json.dumps(r) + "\n" for r in [*seeds, *records])
        dets, report = read_detections_jsonl(
            io.StringIO(text), sensors=self.sizes, max_examples=_MAX_ISSUES
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
        """
        with self._lock:
            dets, ack = self._validate(records)
            stored = self.store.insert_batch(dets, ack, batch_key)
            ack = {
                **stored.report,
                "batch_id": stored.batch_id,
                "detection_ids": list(stored.detection_ids),
                "duplicate": stored.duplicate,
            }
            if stored.duplicate:
                return ack
            for d in dets:
                self._last_t[d.sensor] = max(d.t_s, self._last_t.get(d.sensor, d.t_s))
                self._n_det[d.sensor] = self._n_det.get(d.sensor, 0) + 1
            try:
                self._process(list(zip(stored.detection_ids, dets, strict=True)), ack=ack)
            except Exception:  # the batch is durable; start-up replays what failed here
                log.exception("processing batch %s failed after commit", stored.batch_id)
            return ack

    # -------------------------------------------------------------- processing
    def _process(
        self,
        pending: list[tuple[int, Detection]],
        *,
        ack: dict[str, Any] | None = None,
    ) -> None:
        dets = [d for _, d in pending]
        fixes, _ = build_fixes(self.site, dets)
        by_index = {f.detection_index: f for f in fixes}
        rows: list[tuple[int, float, str, str, str, dict[str, Any]]] = []
        events: list[tuple[str, dict[str, Any]]] = []
        for k, (det_id, d) in enumerate(pending):
            fix = by_index.get(k)
            if fix is None:
                body: dict[str, Any] = {"detection_id": det_id, "hits": None, "tracked": False}
                rows.append((det_id, d.t_s, d.sensor, d.cls, "no_fix", body))
                continue
            body = self._fix_body(det_id, d, fix)
            try:
                self.tracker.update(fix_from_body(body), index=det_id)
            except DemtrackError:  # older than what the tracker already processed
                body["tracked"] = False
                self.n_late += 1
            rows.append((det_id, d.t_s, d.sensor, d.cls, "fix", body))
            events.append(("fix", {"type": "fix", "fix": body}))
        track_rows, track_events = self._track_changes()
        events += track_events
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
        if ack is not None:
            text = (
                f"batch {ack['batch_id']}: {ack['accepted']} of {ack['n_records']} detections"
                f" accepted, {len(fixes)} fixes"
            )
            t = max((d.t_s for d in dets), default=None)
            events.append(("event", {"type": "event", "kind": "ingest", "t_s": t, "text": text}))
        seqs = self.store.write_derived(rows, track_rows, events)
        self.publish([{**p, "seq": s} for (_, p), s in zip(events, seqs, strict=True)])

    def _fix_body(self, det_id: int, d: Detection, fix: Fix) -> dict[str, Any]:
        pts = fix.hits_enu
        if fix.road_hit_enu is not None:
            pts = np.vstack([pts, fix.road_hit_enu[None, :]])
        lat, lon, h = (np.atleast_1d(a) for a in self.site.frame.to_geodetic(*pts.T))
        geo = [(float(a), float(b), float(c)) for a, b, c in zip(lat, lon, h, strict=True)]
        hits = [
            _hit(p, s, geo[k])
            for k, (p, s) in enumerate(zip(fix.hits_enu, fix.hit_sigma_m, strict=True))
        ]
        road = None
        if fix.road_hit_enu is not None:
            sigma = float(np.min(fix.hit_sigma_m)) if len(fix.hit_sigma_m) else 1.0
            road = _hit(fix.road_hit_enu, sigma, geo[-1])
        u0, _, u1, v1 = d.bbox
        return {
            "detection_id": det_id,
            "t_s": d.t_s,
            "sensor": d.sensor,
            "cls": d.cls,
            "score": d.score,
            "bbox": list(d.bbox),
            "foot_pixel": [0.5 * (u0 + u1), v1],
            "origin_enu": [float(x) for x in fix.origin_enu],
            "direction_enu": [float(x) for x in fix.direction_enu],
            "hits": hits,
            "road_hit": road,
            "tracked": True,
        }

    # ------------------------------------------------------------------ tracks
    def track_body(self, track: Track, live: bool, first_index: int = 0) -> dict[str, Any]:
        """JSON body of a track, points from ``first_index`` on."""
        pts = track.points[first_index:]
        if pts:
            p = np.stack([q.p_enu for q in pts])
            lat, lon, h = (np.atleast_1d(a) for a in self.site.frame.to_geodetic(*p.T))
        points = [
            {
                "t_s": q.t_s,
                "e_m": float(q.p_enu[0]),
                "n_m": float(q.p_enu[1]),
                "u_m": float(q.p_enu[2]),
                "lat_deg": float(lat[k]),
                "lon_deg": float(lon[k]),
                "h_m": float(h[k]),
                "sensors": list(q.sensors),
                "detection_ids": list(q.fix_indices),
            }
            for k, q in enumerate(pts)
        ]
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
        self, force: bool = False
    ) -> tuple[list[dict[str, Any]], list[tuple[str, dict[str, Any]]]]:
        """Tracks that changed since the last call: their table rows and stream messages."""
        live_ids = {t.id for t in self.tracker.tracks(include_ended=False)}
        lag = int(getattr(self.tracker.config, "smoothing_lag", 0))
        rows, events = [], []
        for track in self.tracker.tracks():
            if not track.points:
                continue
            live = track.id in live_ids
            p = track.p_enu
            sig = (len(track.points), p[-(lag + 1) :].tobytes(), live)
            prev = self._seen.get(track.id)
            if prev == sig and not force:
                continue
            self._seen[track.id] = sig
            full = self.track_body(track, live)
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
                    "body": full,
                }
            )
            if force:
                continue
            first = 0 if prev is None else max(0, min(prev[0], len(track.points)) - lag - 1)
            tail = dict(full, first_index=first, points=full["points"][first:])
            events.append(("track_update", {"type": "track_update", "track": tail}))
            t_last = track.points[-1].t_s
            if prev is None:
                text = f"track {track.id} ({track.cls}) confirmed"
                events.append(
                    (
                        "event",
                        {"type": "event", "kind": "track_confirmed", "t_s": t_last, "text": text},
                    )
                )
            elif prev[2] and not live:
                text = f"track {track.id} ({track.cls}) ended"
                events.append(
                    ("event", {"type": "event", "kind": "track_ended", "t_s": t_last, "text": text})
                )
        return rows, events
