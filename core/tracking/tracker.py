"""The multi-target, multi-sensor tracker assembled from components.

Processing, per *step* (fixes within ``config.step_window_s`` of the step's first):

1. optionally triangulate same-object pairs from two sensors (:mod:`.fusion`);
2. split into *scans* of equal time and sensor, in time order; per scan:
   a. predict every live track to the scan time;
   b. confirmed tracks: hypothesise each (track, measurement) of the same class and let
      the associator pick one hypothesis per track - a measurement or the explicit
      missed detection - then update;
   b'. single-camera fixes left whose ray passes through a confirmed track's gate are
      that track's object with its hits off it: they feed and seed nothing
      (:mod:`.raygate`; ``config.ray_gate_dz_m``);
   c. tentative tracks: the associator gives each group of siblings (seeds of one fix)
      one measurement among those left; every sibling whose gate holds it updates
      (siblings do not compete, so the right one of "crown or road" is not starved);
   d. measurements nobody took seed tentative tracks (:mod:`.initiation`);
   e. confirm tentative tracks (the best sibling of a group wins, the rest are dropped),
      expire stale ones, end confirmed tracks that coasted too long (:mod:`.deletion`;
      this is also checked before (a), so a track cannot take a fix after too long).

The batch entry point feeds the same :class:`Tracker` one fix at a time, so incremental
and batch use give identical tracks.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import TrackingError
from .config import TrackerConfig
from .fusion import fuse_measurements
from .hypothesiser import CandidateBlock, gate_d2
from .initiation import spread_m
from .protocols import (
    Candidates,
    DataAssociator,
    Deleter,
    Filter,
    Hypothesiser,
    Initiator,
    Measurement,
    MeasurementModel,
    Reacquirer,
    SingleHypothesis,
)
from .raygate import ray_gate
from .reacquire import MotionReacquirer, velocity_gaussian, velocity_prior_density
from .types import Fix, Track, TrackPoint

__all__ = ["ClassComponents", "Tracker", "TrackerComponents", "find_gaps"]


@dataclass(frozen=True)
class ClassComponents:
    """What one object class is tracked with.

    Parameters
    ----------
    measurement : MeasurementModel
        Reads candidates out of a fix.
    filter : Filter
        Predictor/updater (its motion model carries the class's parameters).
    initiator : Initiator
        Seeds and confirms tentative tracks.
    reacquirer : Reacquirer or None
        Scores a lost track's prediction at a new track's position (identity over long
        absences); None: the filter's own prediction (:class:`MotionReacquirer`).
    """

    measurement: MeasurementModel
    filter: Filter
    initiator: Initiator
    reacquirer: Reacquirer | None = None


@dataclass(frozen=True)
class TrackerComponents:
    """A tracker's parts.

    Parameters
    ----------
    per_class : mapping of str to ClassComponents
        Per object class ("vehicle", "human").
    hypothesiser : Hypothesiser
        Gating and cost.
    associator : DataAssociator
        Picks one hypothesis per confirmed track.
    deleter : Deleter
        Ends confirmed tracks.
    fuse : bool
        Triangulate same-object pairs from two sensors.
    ray_gate : bool
        Fixes whose ray passes through a confirmed track's gate seed nothing
        (:mod:`.raygate`; off for the raw baselines, which show what plain hits do).
    """

    per_class: Mapping[str, ClassComponents]
    hypothesiser: Hypothesiser
    associator: DataAssociator
    deleter: Deleter
    fuse: bool = True
    ray_gate: bool = True


@dataclass(eq=False)
class _Record:
    """Mutable bookkeeping of one live or ended track (internal)."""

    uid: int
    group: int
    cls: str
    state: Any
    t_created: float
    t_update: float
    points: list[TrackPoint] = field(default_factory=list)
    n_updates: int = 0
    nis_sum: float = 0.0
    track_id: int | None = None
    #: Candidates behind the points that may still be revised (all while tentative, the
    #: last ``smoothing_lag + 1`` once confirmed).
    cands: list[Candidates] = field(default_factory=list)
    #: While tentative: the state's position spread (m) after each update, oldest first.
    spreads: list[float] = field(default_factory=list)
    #: The last :class:`Track` value made of this record (reused while its points are
    #: the same objects: points are immutable, any change replaces them).
    exported: Track | None = None


#: Up to this many (track, candidate) pairs a scan gates track by track. 0: a hypothesiser
#: that can batch always does (its compiled gating costs less than one track's scalar
#: gating; the two give the same hypotheses).
_BATCH_MIN_PAIRS = 0


def _measurement(fix: Fix, index: int) -> Measurement:
    """``Measurement(fix, (index,), (fix.sensor,))`` without the frozen-field cost."""
    m = object.__new__(Measurement)
    m.__dict__.update(fix=fix, indices=(index,), sensors=(fix.sensor,))
    return m


def _nearest_height(z_enu: list[list[float]], x: float, y: float) -> float:
    """Height of the first candidate horizontally nearest ``(x, y)`` (candidates ``[x, y, z]``).

    In float arithmetic the same squared distances as
    ``np.sum((z[:, :2] - xy) ** 2, axis=1)`` and the same pick as its ``argmin`` (the first
    smallest, or the first NaN).
    """
    near, best = 0, math.inf
    for j, (zx, zy, _) in enumerate(z_enu):
        dx, dy = zx - x, zy - y
        d = dx * dx + dy * dy
        if d != d:  # NaN: argmin's pick
            near = j
            break
        if j == 0 or d < best:
            near, best = j, d
    return z_enu[near][2]


def _best(hyps: Sequence[SingleHypothesis | None]) -> SingleHypothesis | None:
    """Return the gated hypothesis with the smallest distance (None if all are gated out)."""
    real = [h for h in hyps if h is not None]
    return min(real, key=lambda h: h.distance2) if real else None


def find_gaps(t_s: np.ndarray, threshold_s: float) -> list[tuple[float, float]]:
    """Intervals between consecutive times (sorted, (n,)) longer than ``threshold_s``."""
    t = np.asarray(t_s, dtype=np.float64)
    if t.size < 2:
        return []
    dt = np.diff(t)
    return [(float(t[i]), float(t[i + 1])) for i in np.flatnonzero(dt > threshold_s)]


#: How far back from the end :func:`_shared_prefix` looks point by point.
_TAIL_WINDOW = 32


def _shared_prefix(old: tuple[TrackPoint, ...], new: tuple[TrackPoint, ...]) -> int:
    """How many leading points ``old`` and ``new`` share (the same objects).

    A live track changes at its end (new points, the last few revised by smoothing), so
    the shared prefix is looked for within the last :data:`_TAIL_WINDOW` points; 0 when
    the difference lies earlier (a merged or trimmed track).
    """
    m = min(len(old), len(new))
    k = max(0, m - _TAIL_WINDOW)
    if old[:k] != new[:k]:  # identity comparison (eq=False), in C
        return 0
    while k < m and old[k] is new[k]:
        k += 1
    return k


def _grown_track(old: Track, points: tuple[TrackPoint, ...], gap_threshold_s: float) -> Track:
    """The :class:`Track` of ``points``, reusing what ``old`` (same id) already holds.

    Equal to building it from scratch (times, positions, sensors and gaps), at the cost of
    the changed tail rather than the whole history: a long live track changes on every
    batch, and rebuilding its arrays each time made a session's cost grow with its age.
    """
    same = _shared_prefix(old.points, points)
    tail = points[same:]
    t_new = np.fromiter((p.t_s for p in tail), dtype=np.float64, count=len(tail))
    t_s = np.concatenate([old.t_s[:same], t_new])
    p_new = np.stack([p.p_enu for p in tail]) if tail else np.zeros((0, 3))
    p_enu = np.concatenate([old.p_enu[:same], p_new])
    tail_old = frozenset().union(*(p.sensors for p in old.points[same:]))
    tail_new = frozenset().union(*(p.sensors for p in tail))
    if tail_old <= tail_new:
        # union(prefix) | tail_new == old.sensors | tail_new when tail_old <= tail_new
        sensors = old.sensors | tail_new
    else:
        sensors = frozenset().union(*(p.sensors for p in points))
    gaps = find_gaps(t_s, gap_threshold_s)
    track = Track(old.id, old.cls, points, sensors, tuple(gaps))
    t_s.setflags(write=False)
    p_enu.setflags(write=False)
    track.__dict__["t_s"] = t_s  # the cached properties' values, computed already
    track.__dict__["p_enu"] = p_enu
    return track


class Tracker:
    """Online tracker: feed fixes in time order, read tracks at any time.

    Parameters
    ----------
    components : TrackerComponents
        The assembled parts (see :mod:`.methods` for the named methods).
    config : TrackerConfig
        Settings (step window, fusion thresholds, gap threshold, seed).

    Notes
    -----
    :meth:`update` buffers fixes until one arrives past the step window, so that fixes of
    one instant from several cameras are fused; :meth:`step` processes a group at once.
    :meth:`finish` (or :meth:`flush`) processes what is buffered.

    The newest point of a track is the filtered estimate; the ``config.smoothing_lag``
    points before it may still be revised by later fixes (fixed-lag smoothing), so a
    live display should redraw a track's tail rather than only append to it. Ended
    tracks are kept (for :meth:`tracks`); a long-running caller exports them and drops
    the old ones with :meth:`drop_ended`.
    """

    def __init__(self, components: TrackerComponents, config: TrackerConfig) -> None:
        self.components = components
        self.config = config
        self._rng = np.random.default_rng(config.seed)
        self._live: list[_Record] = []
        self._ended: list[_Record] = []
        self._buffer: list[tuple[Fix, int]] = []
        self._n_received = 0
        self._t_done = -np.inf
        self._next_uid = 0
        self._next_group = 0
        self._next_id = 1
        #: Fixes that had no usable measurement (no hit), counted and skipped.
        self.n_unusable = 0
        #: Fixes no track took whose ray passed through a confirmed track's gate (not seeds).
        self.n_explained = 0
        self._gate_d2 = gate_d2(config.gate_probability)

    # ----------------------------------------------------------------- feeding
    def _index(self, index: int | None) -> int:
        i = self._n_received if index is None else int(index)
        self._n_received += 1
        return i

    def _check_time(self, fix: Fix) -> None:
        if fix.t_s < self._t_done:
            raise TrackingError(
                f"fix at t={fix.t_s} s is older than fixes already processed (t={self._t_done} s)"
            )
        if fix.cls not in self.components.per_class:
            raise TrackingError(f"no tracker components for class {fix.cls!r}")

    def update(self, fix: Fix, index: int | None = None) -> None:
        """Add one fix (buffered until the step window of the buffered ones closes).

        Parameters
        ----------
        fix : Fix
            The fix; times must not go back past processed steps.
        index : int or None
            Its index for :attr:`TrackPoint.fix_indices` (default: arrival order).
        """
        self._check_time(fix)
        if self._buffer and fix.t_s - self._buffer[0][0].t_s > self.config.step_window_s:
            self.flush()
        self._buffer.append((fix, self._index(index)))

    def step(self, fixes: Sequence[Fix], indices: Sequence[int] | None = None) -> None:
        """Process ``fixes`` (one instant, any sensors) now, after anything buffered."""
        self.flush()
        if indices is not None and len(indices) != len(fixes):
            raise TrackingError("indices must match fixes one to one")
        group = []
        for k, fix in enumerate(fixes):
            self._check_time(fix)
            group.append((fix, self._index(None if indices is None else indices[k])))
        if group:
            self._process(group)

    def flush(self) -> None:
        """Process the buffered fixes."""
        if self._buffer:
            group, self._buffer = self._buffer, []
            self._process(group)

    def finish(self) -> list[Track]:
        """Flush and return every confirmed track (ended ones included)."""
        self.flush()
        return self.tracks()

    # ----------------------------------------------------------------- reading
    def _to_track(self, rec: _Record) -> Track:
        points = tuple(rec.points)
        old = rec.exported
        # tuple equality compares TrackPoints by identity (eq=False): same objects, same track
        if old is not None and old.id == rec.track_id and old.points == points:
            return old
        if rec.track_id is None:
            raise TrackingError("internal: a tentative track cannot be exported")
        if old is not None and old.id == rec.track_id:
            track = _grown_track(old, points, self.config.gap_threshold_s)
        else:
            sensors = frozenset().union(*(p.sensors for p in points))
            t_s = np.fromiter((p.t_s for p in points), dtype=np.float64, count=len(points))
            gaps = find_gaps(t_s, self.config.gap_threshold_s)
            track = Track(rec.track_id, rec.cls, points, sensors, tuple(gaps))  # type: ignore[arg-type]
        rec.exported = track
        return track

    def tracks(
        self,
        *,
        include_ended: bool = True,
        ended_after_s: float | None = None,
        include_lost: bool = True,
    ) -> list[Track]:
        """Return the confirmed tracks as values, by id (buffered fixes not yet included).

        ``include_ended=False``: only the tracks that have not ended - those still
        updated or coasting, and (with ``include_lost``) the *lost* ones: coasted past
        their class's ``max_coast_s`` but still inside the re-acquisition window
        (``config.reacquire_s``), so a later track may yet take their id. A track has
        *ended* only once that can no longer happen: a live display announces "ended"
        then, not while the object is merely occluded.

        ``ended_after_s``: of the ended (and lost) tracks, only those whose newest point
        is at or after this time (s). A long live session ends thousands of tracks;
        asking for the recent ones costs what they hold, not what every track ever held.
        """
        recs = [r for r in self._live if r.track_id is not None]
        for r in self._ended:
            if not (include_ended or (include_lost and self._lost(r))):
                continue
            if ended_after_s is None or (r.points and r.points[-1].t_s >= ended_after_s):
                recs.append(r)
        return [self._to_track(r) for r in sorted(recs, key=lambda r: r.track_id or 0)]

    def _lost(self, rec: _Record) -> bool:
        """Whether the deleted ``rec`` may still be taken up again (:meth:`_predecessor`)."""
        window = self.config.reacquire_s
        if window <= 0 or rec.track_id is None:
            return False
        if getattr(self.components.per_class[rec.cls].filter, "density", None) is None:
            return False
        # the next scan is at or after ``_t_done``: past the window then, past it for good
        return self._t_done - rec.t_update <= window

    @property
    def n_held(self) -> tuple[int, int]:
        """Track records held in memory: ``(live, ended)`` (live includes tentative)."""
        return len(self._live), len(self._ended)

    def drop_ended(self, before_t_s: float) -> list[int]:
        """Forget ended tracks whose last fix is older than ``before_t_s`` (s).

        Tracks still inside the re-acquisition window (``config.reacquire_s`` before the
        newest processed fix) are kept whatever ``before_t_s`` says, so dropping never
        changes the tracks made afterwards; it only bounds memory. Returns the dropped
        ids; :meth:`tracks` no longer lists them.
        """
        horizon = min(float(before_t_s), self._t_done - self.config.reacquire_s)
        keep: list[_Record] = []
        dropped: list[int] = []
        for rec in self._ended:
            if rec.t_update < horizon and rec.track_id is not None:
                dropped.append(rec.track_id)
            else:
                keep.append(rec)
        self._ended = keep
        return dropped

    def predicted_positions(self, t_s: float) -> dict[int, np.ndarray]:
        """Live confirmed tracks' horizontal means predicted to ``t_s``: id -> (2,)."""
        out = {}
        for rec in self._live:
            if rec.track_id is None:
                continue
            flt = self.components.per_class[rec.cls].filter
            state = flt.predict(rec.state, t_s, np.random.default_rng(0))
            out[rec.track_id] = flt.gaussian(state)[0]
        return out

    # -------------------------------------------------------------- processing
    def _process(self, group: list[tuple[Fix, int]]) -> None:
        meas = [_measurement(f, i) for f, i in group]
        if self.components.fuse and self.config.fuse_sensors and len(meas) > 1:
            meas = fuse_measurements(meas, self.config)
        scans: dict[tuple[float, str], list[Measurement]] = {}
        for m in meas:
            scans.setdefault((m.t_s, m.fix.sensor), []).append(m)
        for key in sorted(scans):
            self._scan(key[0], scans[key])
        self._t_done = max(self._t_done, max(f.t_s for f, _ in group))

    def _candidates(self, meas: Iterable[Measurement]) -> list[tuple[Measurement, Candidates]]:
        out = []
        for m in meas:
            cands = self.components.per_class[m.cls].measurement.candidates(m.fix)
            if cands is None:
                self.n_unusable += 1
            else:
                out.append((m, cands))
        return out

    def _hypothesise(
        self,
        rec: _Record,
        items: Sequence[tuple[Measurement, Candidates]],
        allowed: Sequence[bool],
    ) -> list[SingleHypothesis | None]:
        flt = self.components.per_class[rec.cls].filter
        mean, cov = flt.gaussian(rec.state)
        row: list[SingleHypothesis | None] = []
        for j, (m, cands) in enumerate(items):
            if not allowed[j] or m.cls != rec.cls:
                row.append(None)
            else:
                row.append(self.components.hypothesiser.hypothesise(mean, cov, cands, j))
        return row

    def _hypothesise_all(
        self,
        recs: Sequence[_Record],
        items: Sequence[tuple[Measurement, Candidates]],
        allowed: Sequence[bool],
        block: list[tuple[CandidateBlock, list[str]]],
    ) -> list[list[SingleHypothesis | None]]:
        """:meth:`_hypothesise` for each of ``recs``.

        Batched when the hypothesiser can and the scan is big enough to gain by it;
        ``block`` caches the scan's stacked candidates (filled on first use).
        """
        batched = getattr(self.components.hypothesiser, "hypothesise_tracks", None)
        n_cands = sum(c.size for _, c in items)
        if batched is None or len(recs) * n_cands <= _BATCH_MIN_PAIRS:
            return [self._hypothesise(r, items, allowed) for r in recs]
        if not block:
            classes = [m.cls for m, _ in items]
            block.append((CandidateBlock.stack([c for _, c in items]), classes))
        stacked, classes = block[0]
        per_class = self.components.per_class
        means = np.empty((len(recs), 2))
        covs = np.empty((len(recs), 2, 2))
        rows: dict[str, list[bool]] = {}
        mask = []
        for i, r in enumerate(recs):
            means[i], covs[i] = per_class[r.cls].filter.gaussian(r.state)
            row = rows.get(r.cls)
            if row is None:
                row = rows[r.cls] = [
                    a and c == r.cls for a, c in zip(allowed, classes, strict=True)
                ]
            mask.append(row)
        return batched(means, covs, stacked, np.array(mask, dtype=bool))

    def _apply(
        self, rec: _Record, t: float, m: Measurement, cands: Candidates, hyp: SingleHypothesis
    ) -> None:
        flt = self.components.per_class[rec.cls].filter
        rec.state = flt.update(rec.state, cands, hyp.candidate_index, self._rng)
        rec.n_updates += 1
        rec.nis_sum += hyp.distance2
        rec.t_update = t
        p, cov = flt.estimate(rec.state)
        rec.points.append(TrackPoint._made(t, p, m.sensors, m.indices, cov))
        rec.cands.append(cands)
        if rec.track_id is None:
            rec.spreads.append(spread_m(flt.gaussian(rec.state)[1]))
        else:
            lag = self.config.smoothing_lag
            self._revise(rec, min(lag + 1, len(rec.cands)))
            del rec.cands[: -(lag + 1)]

    def _scan(self, t: float, meas: list[Measurement]) -> None:
        items = self._candidates(meas)
        # every track is gated against every measurement: candidates stacked once
        block: list[tuple[CandidateBlock, list[str]]] = []
        # End what coasted too long before it can take a fix: identity is not kept
        # across an absence longer than the limit, however wide the gate has grown.
        self._confirm_and_delete(t)
        for rec in self._live:
            flt = self.components.per_class[rec.cls].filter
            rec.state = flt.predict(rec.state, t, self._rng)
        taken = [False] * len(items)

        confirmed = [r for r in self._live if r.track_id is not None]
        if confirmed and items:
            allowed = [True] * len(items)
            rows = self._hypothesise_all(confirmed, items, allowed, block)
            for rec, hyp in zip(
                confirmed, self.components.associator.associate(rows, len(items)), strict=True
            ):
                if isinstance(hyp, SingleHypothesis):
                    m, cands = items[hyp.measurement_index]
                    self._apply(rec, t, m, cands, hyp)
                    taken[hyp.measurement_index] = True

        # A single camera's fix no confirmed track took, whose ray passes through one's
        # gate, is that track's object seen with its hits off the object (a crest's far
        # crossing, ground metres off along the ray): neither food for a tentative track
        # nor a seed, or a phantom shadows the real track along the ray (:mod:`.raygate`).
        if confirmed and self.components.ray_gate and self.config.ray_gate_dz_m is not None:
            self._explained(confirmed, items, taken)

        # Tentative tracks compete group against group (so a false alarm's seed cannot
        # feed on a real object's fixes beside that object's own seed), but siblings of
        # one group share: each sibling in whose gate the group's measurement lies takes it.
        free = [not k for k in taken]
        groups: dict[int, list[_Record]] = {}
        for rec in self._live:
            if rec.track_id is None:
                groups.setdefault(rec.group, []).append(rec)
        if groups and any(free):
            keys = sorted(groups)
            tentative = [r for g in keys for r in groups[g]]
            flat = iter(self._hypothesise_all(tentative, items, free, block))
            sib_rows = {g: [next(flat) for _ in groups[g]] for g in keys}
            group_rows = [
                [_best([row[j] for row in sib_rows[g]]) for j in range(len(items))] for g in keys
            ]
            choice = self.components.associator.associate(group_rows, len(items))
            for g, hyp in zip(keys, choice, strict=True):
                if not isinstance(hyp, SingleHypothesis):
                    continue
                j = hyp.measurement_index
                m, cands = items[j]
                for rec, row in zip(groups[g], sib_rows[g], strict=True):
                    own = row[j]
                    if own is not None:
                        self._apply(rec, t, m, cands, own)
                taken[j] = True

        for j, (m, cands) in enumerate(items):
            if not taken[j]:
                self._seed(t, m, cands)
        self._confirm_and_delete(t)

    def _explained(
        self,
        confirmed: Sequence[_Record],
        items: Sequence[tuple[Measurement, Candidates]],
        taken: list[bool],
    ) -> None:
        """Mark as taken the free single-sensor fixes a confirmed track's ray gate holds."""
        dz_max = self.config.ray_gate_dz_m
        if dz_max is None:
            return
        by_cls: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for j, (m, _) in enumerate(items):
            if taken[j] or len(m.indices) != 1:
                continue
            tracks = by_cls.get(m.cls)
            if tracks is None:
                recs = [r for r in confirmed if r.cls == m.cls]
                flt = self.components.per_class[m.cls].filter
                gauss = [flt.gaussian(r.state) for r in recs]
                tracks = by_cls[m.cls] = (
                    np.array([g[0] for g in gauss]).reshape(-1, 2),
                    np.array([g[1] for g in gauss]).reshape(-1, 2, 2),
                    np.array([r.points[-1].p_enu[2] for r in recs]),
                )
            if not len(tracks[2]):
                continue
            fix = m.fix
            if ray_gate(fix.origin_enu, fix.direction_enu, *tracks, self._gate_d2, dz_max).any():
                taken[j] = True
                self.n_explained += 1

    def _seed(self, t: float, m: Measurement, cands: Candidates) -> None:
        parts = self.components.per_class[m.cls]
        group = self._next_group
        self._next_group += 1
        for which in parts.initiator.seeds(cands):
            state = parts.filter.initiate(cands, which, t, self._rng)
            rec = _Record(self._next_uid, group, m.cls, state, t, t)
            self._next_uid += 1
            p, cov = parts.filter.estimate(state)
            rec.points.append(TrackPoint._made(t, p, m.sensors, m.indices, cov))
            rec.cands.append(cands)
            rec.spreads.append(spread_m(parts.filter.gaussian(state)[1]))
            rec.n_updates = 1
            self._live.append(rec)

    def _revise(self, rec: _Record, n: int) -> None:
        """Let the filter re-estimate the last ``n`` points (fixed-lag smoothing).

        ``z`` of a revised point is that of its fix's candidate nearest the new position.
        A filter with ``revise_xy`` (:class:`~.kalman.KalmanFilter`) hands the positions
        over as one (r, 2) array rather than a list of rows.
        """
        flt = self.components.per_class[rec.cls].filter
        as_array = getattr(flt, "revise_xy", None)
        revised = flt.revise(rec.state, n) if as_array is None else as_array(rec.state, n)
        if len(revised) == 0:
            return
        first = len(rec.points) - len(revised)
        offset = len(rec.cands) - len(rec.points)
        # all revised positions in one (r, 3) array, checked once; each point gets its row
        p_all = np.empty((len(revised), 3))
        p_all[:, :2] = revised
        cands = rec.cands
        heights = []
        total = 0.0  # finite only if every coordinate is (an overflow takes the long way)
        for k, (x, y) in enumerate(p_all[:, :2].tolist()):
            z = cands[first + k + offset].z_enu
            h = z.item(0, 2) if len(z) == 1 else _nearest_height(z.tolist(), x, y)
            heights.append(h)
            total += x + y + h
        p_all[:, 2] = heights
        if not math.isfinite(total) and not np.isfinite(p_all).all():
            raise TrackingError("p_enu must be finite")
        points = rec.points
        for k, row in enumerate(p_all, start=first):
            p = row.copy()  # a point's own array (a view would keep all the rows alive)
            p.setflags(write=False)
            points[k] = points[k]._moved_trusted(p)

    def _confirm(self, rec: _Record, t: float) -> None:
        """Give ``rec`` an id and let its filter revise the points made while tentative.

        Points made before the state first settled are left out
        (:meth:`Initiator.reportable`). The id is that of an earlier track when
        :meth:`_predecessor` finds one (the same object, back after an absence); otherwise
        a new one.
        """
        skip = self.components.per_class[rec.cls].initiator.reportable(rec.spreads)
        skip = min(skip, len(rec.points) - 1)
        if skip > 0:
            del rec.points[:skip]
            del rec.cands[:skip]
        rec.spreads = []
        self._revise(rec, len(rec.points))
        del rec.cands[: -(self.config.smoothing_lag + 1)]
        old = self._predecessor(rec, t)
        if old is None:
            rec.track_id = self._next_id
            self._next_id += 1
            return
        rec.track_id = old.track_id
        rec.points = old.points + rec.points
        rec.t_created = old.t_created
        if old in self._live:
            self._live.remove(old)
        else:
            self._ended.remove(old)

    def _predecessor(self, rec: _Record, t: float) -> _Record | None:
        """The lost track of ``rec``'s class that best explains ``rec`` (or None).

        Candidates: confirmed tracks, live (coasting) or ended less than
        ``config.reacquire_s`` ago, whose last fix precedes ``rec``'s first (so the two
        were never seen at once: they cannot be two objects side by side). Each one's
        state is predicted to ``t`` by its own motion model, and the density it gives
        ``rec``'s position (with ``rec``'s covariance) must beat the clutter density. Where
        both states have a velocity the density is joint over position and velocity, and
        the clutter density is multiplied by the density a new track's velocity prior
        (zero mean, the class's ``init_speed_sigma_m_s``) gives ``rec``'s velocity: an
        object moving against the lost one's predicted motion is not taken for it.
        """
        window = self.config.reacquire_s
        if window <= 0:
            return None
        parts = self.components.per_class[rec.cls]
        flt = parts.filter
        if getattr(flt, "density", None) is None:
            return None
        reacquirer = parts.reacquirer or MotionReacquirer()
        xy, cov = flt.gaussian(rec.state)
        pool = [r for r in self._live if r.track_id is not None] + [
            r for r in self._ended if t - r.t_update <= window
        ]
        # With a velocity on both sides the densities are joint over position and
        # velocity; "a new object" then has the clutter density times what the velocity
        # prior of a new track gives the new track's velocity.
        vel = velocity_gaussian(rec.state)
        v_xy, cov_v = (None, None) if vel is None else vel
        threshold = self.config.clutter_density_per_m2
        if vel is not None:
            speed_sigma = self.config.params(rec.cls).init_speed_sigma_m_s
            threshold *= velocity_prior_density(vel[0], vel[1], speed_sigma)
        best, best_density = None, threshold
        for old in pool:
            if old.cls != rec.cls or old.t_update >= rec.t_created:
                continue
            # a private generator: looking must not change the tracker's random stream
            last = old.points[-1]
            d = reacquirer.density(
                flt,
                old.state,
                last.t_s,
                last.p_enu[:2],
                t,
                xy,
                cov,
                np.random.default_rng(old.uid),
                v_xy=v_xy,
                cov_v=cov_v,
            )
            if d > best_density:
                best, best_density = old, d
        return best

    def _confirm_and_delete(self, t: float) -> None:
        per_class = self.components.per_class
        winners: dict[int, _Record] = {}
        for rec in self._live:
            if rec.track_id is not None:
                continue
            spread = rec.spreads[-1] if rec.spreads else 0.0
            if per_class[rec.cls].initiator.confirmed(rec.n_updates, t - rec.t_created, spread):
                best = winners.get(rec.group)
                key = (-rec.n_updates, rec.nis_sum / max(rec.n_updates - 1, 1), rec.uid)
                if best is None or key < (
                    -best.n_updates,
                    best.nis_sum / max(best.n_updates - 1, 1),
                    best.uid,
                ):
                    winners[rec.group] = rec
        for group in sorted(winners, key=lambda g: winners[g].uid):
            self._confirm(winners[group], t)
        keep: list[_Record] = []
        for rec in self._live:
            if rec.track_id is None:
                if rec.group in winners:
                    continue  # a sibling won
                if per_class[rec.cls].initiator.expired(rec.n_updates, t - rec.t_created):
                    continue
                keep.append(rec)
            elif self.components.deleter.delete(rec.cls, t - rec.t_update):
                self._ended.append(rec)
            else:
                keep.append(rec)
        self._live = keep
