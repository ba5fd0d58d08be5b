"""Live activity events: the detectors and hand-off prediction run on the tracker's tracks.

:class:`LiveEvents` is called by the pipeline after each batch with the tracks as they
stand and the scenario time the tracker has reached. Every ``every_s`` of scenario time it
runs :mod:`demtrack.core.activity.detectors` (loitering, rendezvous, convoy, zone enter/leave) on
the last ``window_s`` of every track, thinned to points ``sample_s`` apart, and
:func:`demtrack.core.visibility.handoff.predict_handoff` on each live track; the cost per evaluation
is bounded by the window, not by how long the server has run.

Episodes are deduplicated: a loitering, rendezvous or convoy found again (same kind and
targets, overlapping or touching the known episode in time) extends the known one instead
of starting another, and so does a convoy whose members are a subset or superset of an open
convoy's (a vehicle joined or left the column: the episode's ``track_ids`` change, its key
stays); it is closed when an evaluation no longer finds it or its end lags
the present by more than ``2 * every_s + 2 * sample_s + 1`` s (the targets moved on), and
is not announced again while the window still holds it. Zone crossings
are instantaneous: one per track, zone and direction within ``2 * every_s``.

A hand-off prediction is not something that happened but an annotation on a live track:
each track has one, keyed ``handoff:<track id>`` (so the stored row is replaced, never a
new row per evaluation), reported again (streamed with the same key) only when its
(current sensor, next sensor) pair changes: at once when the current sensor changes, and
when only the next sensor does, once the new one has held for :data:`HANDOFF_HOLD`
evaluations in a row (two cameras about equally likely would otherwise flip the
prediction every evaluation). ``/api/events`` leaves predictions out unless asked
(``kind=handoff``); the console shows them in the track's detail, not in the event list.

Each event is a JSON-ready dict (the body of the ``activity`` table and of the
``event`` stream message's ``event`` field): ``key`` (stable identity), ``kind``,
``state`` (``start``, ``update`` or ``end``), ``t_start_s``, ``t_end_s``,
``track_ids``, ``sensors``, ``p_enu``, ``lat_deg``, ``lon_deg``, ``h_m``, ``details``
and ``open``. A body once returned is never changed here (an update is a new dict), so
it can be published while the next evaluation runs.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from demtrack.core.activity.convoy import ConvoyParams, detect_convoys
from demtrack.core.activity.detectors import ActivityEvent
from demtrack.core.activity.kinds import INTERVAL_KINDS, EventKind
from demtrack.core.activity.loitering import LoiterParams, detect_loitering
from demtrack.core.activity.rendezvous import RendezvousParams, detect_rendezvous
from demtrack.core.activity.zones import Zone, detect_zone_crossings
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Track
from demtrack.core.visibility.handoff import HandoffTarget, predict_handoffs
from demtrack.core.visibility.target_heights import target_height_for

__all__ = ["HANDOFF_HOLD", "LiveEventParams", "LiveEvents", "Window"]

#: Evaluations in a row a changed next sensor must hold before it replaces a prediction.
HANDOFF_HOLD = 3


@dataclass(frozen=True)
class LiveEventParams:
    """How often, over what, and with which detector parameters (see the settings)."""

    every_s: float = 1.0
    window_s: float = 180.0
    sample_s: float = 0.5
    loiter: LoiterParams = field(default_factory=LoiterParams)
    rendezvous: RendezvousParams = field(default_factory=RendezvousParams)
    convoy: ConvoyParams = field(default_factory=ConvoyParams)
    zones: tuple[Zone, ...] = ()
    handoff_horizon_s: float = 10.0
    handoff_dt_s: float = 1.0


@dataclass(frozen=True, eq=False)
class Window:
    """A track's points inside the evaluation window, thinned (what the detectors read).

    ``index`` (n,) holds the kept points' indices in ``track.points``; ``sensors`` (each
    kept point's sensors) is read from them when first needed (only an event's body reads
    it).
    """

    id: int
    cls: str
    t_s: np.ndarray
    p_enu: np.ndarray
    track: Track
    index: np.ndarray

    @functools.cached_property
    def sensors(self) -> tuple[tuple[str, ...], ...]:
        """Each kept point's sensors."""
        points = self.track.points
        return tuple(points[k].sensors for k in self.index.tolist())


#: Times this close (s) to a thinning grid point count as on it (camera clocks are
#: microseconds; float64 UNIX times have a 2.4e-7 s grain).
_THIN_TOL_S = 1e-6


def _thin(track: Track, t_from: float, sample_s: float) -> Window | None:
    """``track`` from ``t_from`` on, thinned to points ``sample_s`` apart."""
    t = track.t_s
    k0 = int(np.searchsorted(t, t_from - _THIN_TOL_S))  # a point on the window's start is in
    if k0 >= len(t):
        return None
    t = t[k0:]
    # On times relative to the window's first point, with a microsecond of tolerance:
    # a grid built on UNIX times (1.8e9 s, float64 grain 2.4e-7 s) would pick its
    # points by rounding ties, and thin the same track differently at another epoch.
    rel = t - t[0]
    grid = np.arange(0.0, rel[-1] + sample_s, sample_s) - _THIN_TOL_S
    # sorted already (the grid increases): unique = drop repeats, then the last point
    keep = np.minimum(np.searchsorted(rel, grid), len(t) - 1)
    keep = keep[np.concatenate(([True], keep[1:] != keep[:-1]))[: len(keep)]]
    if not len(keep) or keep[-1] != len(t) - 1:
        keep = np.append(keep, len(t) - 1)
    index = keep + k0
    # the track's cached (n, 3) positions: the points' own values, stacked once per track
    return Window(track.id, track.cls, t[keep], track.p_enu[index], track, index)


def _identity(e: ActivityEvent) -> str:
    return _identity_of(e.kind, e.track_ids, e.details.get("zone"))


def _identity_of(kind: str, track_ids: Sequence[int], zone: Any = None) -> str:
    """An episode's identity: its kind, its targets (in id order) and its zone, if any."""
    ids = ",".join(str(i) for i in sorted(track_ids))
    return f"{kind}:{ids}" + (f":{zone}" if zone is not None else "")


class LiveEvents:
    """Incremental event detection over a sliding window (see the module docstring).

    Parameters
    ----------
    site : Site
        DEM, sensors and roads (for hand-off prediction).
    params : LiveEventParams
    known : sequence of dict
        Stored bodies still open, and each track's newest hand-off (after a restart).
    """

    def __init__(self, site: Site, params: LiveEventParams, known: Sequence[dict] = ()) -> None:
        self.site = site
        self.params = params
        self.last_eval_t: float | None = None
        self._open: dict[str, dict[str, Any]] = {}
        self._crossings: dict[str, float] = {}
        self._closed: dict[str, float] = {}
        self._handoff: dict[int, tuple[str | None, str | None]] = {}
        # a track's new (current, next) pair and how many evaluations in a row gave it
        self._pending: dict[int, tuple[tuple[str | None, str | None], int]] = {}
        for body in known:
            if body["kind"] == EventKind.HANDOFF:
                d = body["details"]
                self._handoff[body["track_ids"][0]] = (d.get("current"), d.get("next_sensor"))
            elif body.get("open"):
                self._open[body["identity"]] = body

    # ------------------------------------------------------------------ helpers
    def _body(self, e: ActivityEvent, windows: Mapping[int, Window], identity: str) -> dict:
        sensors = sorted(
            {
                s
                for tid in e.track_ids
                if tid in windows
                for k, t in enumerate(windows[tid].t_s)
                if e.t_start_s <= t <= e.t_end_s
                for s in windows[tid].sensors[k]
            }
        )
        return {
            "key": f"{identity}@{e.t_start_s:.3f}",
            "identity": identity,
            "kind": e.kind,
            "state": "start",
            "t_start_s": float(e.t_start_s),
            "t_end_s": float(e.t_end_s),
            "track_ids": [int(i) for i in e.track_ids],
            "sensors": sensors,
            "p_enu": [float(v) for v in e.p_enu],
            "details": _jsonable(e.details),
            "open": e.kind in INTERVAL_KINDS,
        }

    def _geo(self, body: dict[str, Any]) -> dict[str, Any]:
        lat, lon, h = (float(v) for v in self.site.frame.to_geodetic(*body["p_enu"]))
        body.update(lat_deg=lat, lon_deg=lon, h_m=h)
        return body

    def due(self, t_now: float) -> bool:
        """Whether an evaluation is due at scenario time ``t_now`` (s)."""
        return self.last_eval_t is None or t_now - self.last_eval_t >= self.params.every_s

    # --------------------------------------------------------------- evaluation
    def evaluate(
        self, tracks: Sequence[Track], live_ids: set[int], t_now: float
    ) -> list[tuple[dict[str, Any], bool]]:
        """Run the detectors at ``t_now``: new, changed and closed event bodies.

        Each body comes with whether it is news for the stream: a start, an end, or an
        update whose members changed (a convoy a vehicle joined or left). An update that
        only grows the episode's span is stored, not streamed: a console learns the
        final span from the end.
        """
        prm = self.params
        self.last_eval_t = t_now
        t_from = t_now - prm.window_s
        # An episode is over once its end lags the present by more than this (s).
        stale = 2 * prm.every_s + 2 * prm.sample_s + 1.0
        touch = prm.every_s + prm.sample_s
        # A track that ended longer ago than that plus the longest convoy lag (and an
        # evaluation since) can take part in no event still to be announced or extended:
        # its loitering, zone crossings and rendezvous end when it does, a convoy it leads
        # at most ``max_lag_s`` later (the follower's time), so they are stale or already
        # reported; an open episode was closed by the evaluation after it went stale.
        # Leaving such tracks out keeps the detectors' cost (pairs, for rendezvous and
        # convoys) to the tracks of the present, not everything the window still holds.
        recent = t_now - stale - prm.every_s - prm.convoy.max_lag_s - 1.0
        windows = {}
        for tr in tracks:
            if not tr.points or tr.points[-1].t_s < t_from:
                continue
            if self._in_play(tr, live_ids, recent):
                w = _thin(tr, t_from, prm.sample_s)
                if w is not None:
                    windows[w.id] = w
        ws = list(windows.values())
        out: list[dict[str, Any]] = []
        news: set[int] = set()  # id() of the updates in ``out`` the stream must carry
        found = detect_loitering(ws, prm.loiter) + detect_rendezvous(ws, prm.rendezvous)
        found += detect_convoys([w for w in ws if w.cls == "vehicle"], prm.convoy)
        seen: set[str] = set()
        for e in found:
            ident = _identity(e)
            closed = self._closed.get(ident)
            if closed is not None and e.t_start_s <= closed + touch:
                continue  # the window still holds an episode already closed
            going_on = self._continued(e, ident, touch)
            if going_on is not None:
                seen.add(going_on)
                before = self._open[going_on]["track_ids"]
                grown = self._extend(going_on, e, windows)
                if grown is not None:
                    out.append(grown)
                    if grown["track_ids"] != before:  # every membership change is news
                        news.add(id(grown))
                continue
            old = self._open.get(ident)
            if ident in seen:
                continue
            if old is not None:  # a new episode of the same targets: close the old one
                out.append(self._close(ident))
            if t_now - e.t_end_s > stale:
                continue  # over before it was seen (e.g. after a restart): not announced
            body = self._geo(self._body(e, windows, ident))
            self._open[ident] = body
            seen.add(ident)
            out.append(body)
        for ident in list(self._open):
            if ident not in seen or t_now - self._open[ident]["t_end_s"] > stale:
                out.append(self._close(ident))
        self._closed = {k: t for k, t in self._closed.items() if t >= t_from}
        if prm.zones:
            out += self._zone_events(ws, windows, t_now)
        if prm.handoff_horizon_s > 0:
            out += self._handoffs(tracks, live_ids, t_now)
        return [(b, b["state"] != "update" or id(b) in news) for b in out]

    def _continued(self, e: ActivityEvent, ident: str, touch: float) -> str | None:
        """The identity of the open episode ``e`` continues, if any.

        The episode of the same kind and targets that ``e`` overlaps or touches in time;
        for a convoy also one whose members are a subset or superset of ``e``'s (a
        vehicle joined or left the column): one episode whose members change, not a new
        event per membership. Among several, the one sharing most members, then the
        oldest.
        """
        old = self._open.get(ident)
        if old is not None and e.t_start_s <= old["t_end_s"] + touch:
            return ident
        if e.kind != EventKind.CONVOY:
            return None
        members = set(e.track_ids)
        best: tuple[int, float, str] | None = None
        for other, body in self._open.items():
            if body["kind"] != EventKind.CONVOY or e.t_start_s > body["t_end_s"] + touch:
                continue
            theirs = set(body["track_ids"])
            if not (members <= theirs or theirs <= members):
                continue
            rank = (-len(members & theirs), body["t_start_s"], other)
            if best is None or rank < best:
                best = rank
        return None if best is None else best[2]

    def _extend(
        self, ident: str, e: ActivityEvent, windows: Mapping[int, Window]
    ) -> dict[str, Any] | None:
        """The open episode ``ident`` grown by ``e`` (span, details, members, sensors).

        None when ``e`` changes neither its span nor its members.
        """
        old = self._open[ident]
        t0, t1 = min(old["t_start_s"], e.t_start_s), max(old["t_end_s"], e.t_end_s)
        members = [int(i) for i in e.track_ids]
        if (t0, t1) == (old["t_start_s"], old["t_end_s"]) and members == old["track_ids"]:
            return None
        sensors = sorted({*old["sensors"], *self._body(e, windows, ident)["sensors"]})
        # a new dict: bodies already returned may still be on their way out
        new = dict(
            old,
            t_start_s=t0,
            t_end_s=t1,
            state="update",
            details=_jsonable(e.details),
            track_ids=members,
            sensors=sensors,
        )
        self._open[ident] = new
        return new

    @staticmethod
    def _in_play(track: Track, live_ids: set[int], recent_s: float) -> bool:
        """Whether ``track`` may still take part in a new or growing event."""
        return track.id in live_ids or track.points[-1].t_s >= recent_s

    def _close(self, ident: str) -> dict[str, Any]:
        body = dict(self._open.pop(ident), state="end", open=False)
        self._closed[ident] = body["t_end_s"]
        # an episode whose members changed is also over for its last members' identity
        zone = body["details"].get("zone")
        self._closed[_identity_of(body["kind"], body["track_ids"], zone)] = body["t_end_s"]
        return body

    def _zone_events(
        self, ws: list[Window], windows: Mapping[int, Window], t_now: float
    ) -> list[dict[str, Any]]:
        out = []
        horizon = 2 * self.params.every_s
        for e in detect_zone_crossings(ws, self.params.zones):
            ident = _identity(e)
            last = self._crossings.get(ident)
            if last is not None and abs(e.t_start_s - last) <= horizon:
                continue
            if last is not None and e.t_start_s < last:
                continue  # an older crossing already reported (window re-read)
            self._crossings[ident] = e.t_start_s
            out.append(self._geo(self._body(e, windows, ident)))
        cutoff = t_now - self.params.window_s
        self._crossings = {k: t for k, t in self._crossings.items() if t >= cutoff}
        return out

    def _handoffs(
        self, tracks: Sequence[Track], live_ids: set[int], t_now: float
    ) -> list[dict[str, Any]]:
        prm = self.params
        out = []
        moving: list[tuple[Track, np.ndarray, HandoffTarget]] = []
        for tr in tracks:
            if tr.id not in live_ids or len(tr.points) < 2:
                continue
            t = tr.t_s
            last = tr.points[-1]
            k = max(0, int(np.searchsorted(t, t[-1] - 1.0)) - 1)
            if t[-1] - t[k] <= 0:
                continue
            v = (last.p_enu - tr.points[k].p_enu) / (t[-1] - t[k])
            current = sorted(last.sensors)[0] if last.sensors else None
            target = HandoffTarget(
                last.p_enu,
                v,
                current if current in self.site.sensors else None,
                target_height_for(tr.cls),
                self.site.roads if tr.cls == "vehicle" else None,
            )
            moving.append((tr, v, target))
        preds = predict_handoffs(
            self.site.dem,
            self.site.sensors,
            [target for _, _, target in moving],
            horizon_s=prm.handoff_horizon_s,
            dt_s=prm.handoff_dt_s,
        )
        for (tr, v, _), pred in zip(moving, preds, strict=True):
            t = tr.t_s
            last = tr.points[-1]
            pair = (pred.current, pred.next_sensor)
            if pred.exit_in_s is None or pred.next_sensor is None:
                continue
            known = self._handoff.get(tr.id)
            if known == pair:
                self._pending.pop(tr.id, None)
                continue
            if known is not None and known[0] == pair[0]:
                # Only the next sensor differs: two cameras about equally likely flip from
                # one evaluation to the next; the prediction changes once the new one has
                # held for HANDOFF_HOLD evaluations in a row.
                seen, n = self._pending.get(tr.id, (None, 0))
                n = n + 1 if seen == pair else 1
                self._pending[tr.id] = (pair, n)
                if n < HANDOFF_HOLD:
                    continue
            self._pending.pop(tr.id, None)
            self._handoff[tr.id] = pair
            acq = pred.acquisition_enu
            where = last.p_enu if acq is None else acq
            details = {
                "current": pred.current,
                "next_sensor": pred.next_sensor,
                "exit_t_s": float(t[-1] + pred.exit_in_s),
                "next_t_s": None if pred.next_in_s is None else float(t[-1] + pred.next_in_s),
                "slew": bool(pred.slew),
                "pan_deg": pred.pan_deg,
                "tilt_deg": pred.tilt_deg,
                "speed_mps": float(np.hypot(v[0], v[1])),
            }
            e = ActivityEvent(
                EventKind.HANDOFF.value,
                float(t[-1]),
                details["exit_t_s"],
                (tr.id,),
                where,
                details,
            )
            # One prediction per track, replaced: the same key every time (the stored row
            # is updated in place, a console replaces it by key). Each new prediction is a
            # "start": a new statement, not the growth of an episode.
            ident = f"{EventKind.HANDOFF}:{tr.id}"
            body = self._body(e, {}, ident)
            body["key"] = ident
            body["sensors"] = [s for s in pair if s is not None]
            out.append(self._geo(body))
        self._handoff = {k: v for k, v in self._handoff.items() if k in live_ids}
        self._pending = {k: v for k, v in self._pending.items() if k in live_ids}
        return out


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj
