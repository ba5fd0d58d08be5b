"""Score the activity detectors on the activity cases: precision and recall per detector.

The chain is the operator console's: detections -> fixes (:func:`build_fixes`) -> tracker
(default method) -> detectors (:mod:`demtrack.core.activity.detectors`, default parameters).
Detected
events are matched to the case's true events (:mod:`.activity_scenarios`):

- each track is assigned to a true target (:func:`~demtrack.core.tracking.metrics.match_tracks`:
  same class, median distance at most 5 m); an event on an unassigned track matches nothing;
- a detected event matches a true event of the same kind whose targets are exactly the
  targets of the event's tracks (as sets), when their times overlap: the intersection,
  plus a slack ``tol_s``, is at least ``min_share`` of the shorter interval (for a zone
  crossing, an instant: within ``tol_s``).

Recall is the share of true events matched; precision the share of detected events that
match some true event (a true event reported twice, e.g. on two fragments of a track,
counts as correct twice and is listed as a duplicate). Zone entries and exits are scored
together as the ``zone`` detector. A near-miss fires when its detector reports an event
of its kind whose targets include all of the near-miss's targets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from demtrack.core.activity.convoy import detect_convoys
from demtrack.core.activity.detectors import ActivityEvent
from demtrack.core.activity.loitering import detect_loitering
from demtrack.core.activity.rendezvous import detect_rendezvous
from demtrack.core.activity.zones import Zone, detect_zone_crossings
from demtrack.core.geolocation.fix_builder import build_fixes
from demtrack.core.site.folder import Site
from demtrack.core.tracking import run_tracker
from demtrack.core.tracking.metrics import match_tracks

from .activity_scenarios import ActivityScenario, NearMiss, TrueEvent

__all__ = [
    "DETECTORS",
    "CaseResult",
    "DetectorScore",
    "detect_all",
    "detector_of",
    "evaluate_case",
    "match_events",
    "score_detectors",
]

#: Detector name per event kind.
DETECTORS = ("loitering", "rendezvous", "convoy", "zone")


def detector_of(kind: str) -> str:
    """The detector that reports events of ``kind`` (``zone-enter`` -> ``zone``)."""
    return "zone" if kind.startswith("zone-") else kind


def detect_all(trajectories: Sequence[Any], zones: Sequence[Zone]) -> list[ActivityEvent]:
    """Every detector with its default parameters, events in time order."""
    events = (
        detect_loitering(trajectories)
        + detect_rendezvous(trajectories)
        + detect_convoys(trajectories)
        + detect_zone_crossings(trajectories, zones)
    )
    return sorted(events, key=lambda e: (e.t_start_s, e.kind))


def _times_match(
    t0: float, t1: float, u0: float, u1: float, tol_s: float, min_share: float
) -> bool:
    inter = min(t1, u1) - max(t0, u0) + tol_s
    shorter = min(t1 - t0, u1 - u0)
    return inter >= 0 and inter >= min_share * shorter


def match_events(
    detected: Sequence[ActivityEvent],
    truth_of: dict[int, int | None],
    true_events: Sequence[TrueEvent],
    *,
    tol_s: float = 2.0,
    min_share: float = 0.5,
) -> list[int | None]:
    """For each detected event, the index of the true event it matches (or None).

    Parameters
    ----------
    detected : sequence of ActivityEvent
        Events on tracks (``track_ids`` are track ids).
    truth_of : dict of int to int or None
        Track id -> true target id (None: a false track).
    true_events : sequence of TrueEvent
        What really happened.
    tol_s : float
        Time slack (s): instants match within it.
    min_share : float
        Share of the shorter interval that must overlap.
    """
    out: list[int | None] = []
    for ev in detected:
        targets = [truth_of.get(t) for t in ev.track_ids]
        best = None
        if None not in targets:
            for k, te in enumerate(true_events):
                if (
                    te.kind == ev.kind
                    and set(te.target_ids) == set(targets)
                    and _times_match(
                        te.t_start_s, te.t_end_s, ev.t_start_s, ev.t_end_s, tol_s, min_share
                    )
                ):
                    best = k
                    break
        out.append(best)
    return out


def _fired(near: NearMiss, detected: Sequence[ActivityEvent], truth_of: dict[int, int | None]):
    for ev in detected:
        targets = {truth_of.get(t) for t in ev.track_ids}
        if ev.kind == near.kind and set(near.target_ids) <= targets:
            return True
    return False


@dataclass(frozen=True)
class CaseResult:
    """One case's outcome.

    Attributes
    ----------
    name : str
        Case name.
    source : str
        ``tracks`` (the full chain) or ``truth`` (detectors on the true paths).
    true_events : tuple of TrueEvent
    detected : tuple of ActivityEvent
        On tracks (track ids) or on truth (target ids).
    matches : tuple of int or None
        Per detected event, the true event it matches.
    truth_of : dict of int to int or None
        Track id -> target id.
    near_misses_fired : tuple of (NearMiss, bool)
    n_tracks : int
    """

    name: str
    source: str
    true_events: tuple[TrueEvent, ...]
    detected: tuple[ActivityEvent, ...]
    matches: tuple[int | None, ...]
    truth_of: dict[int, int | None] = field(default_factory=dict)
    near_misses_fired: tuple[tuple[NearMiss, bool], ...] = ()
    n_tracks: int = 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "case": self.name,
            "source": self.source,
            "tracks": self.n_tracks,
            "track_to_target": {str(k): v for k, v in self.truth_of.items()},
            "true_events": [e.to_dict() for e in self.true_events],
            "detected": [
                {
                    "kind": e.kind,
                    "track_ids": list(e.track_ids),
                    "t_start_s": round(e.t_start_s, 2),
                    "t_end_s": round(e.t_end_s, 2),
                    "matches_true_event": m,
                }
                for e, m in zip(self.detected, self.matches, strict=True)
            ],
            "near_misses": [
                {"kind": n.kind, "target_ids": list(n.target_ids), "note": n.note, "fired": f}
                for n, f in self.near_misses_fired
            ],
        }


def evaluate_case(
    site: Site, activity: ActivityScenario, method: str, *, source: str = "tracks"
) -> CaseResult:
    """Run the chain on one rendered case and match its events.

    ``source="truth"`` runs the detectors on the true paths instead of tracks (the
    detectors' own error, without the tracker's).
    """
    sc, case = activity.scenario, activity.case
    if source == "truth":
        trajectories: list[Any] = list(sc.truths)
        truth_of: dict[int, int | None] = {t.target_id: t.target_id for t in sc.truths}
    else:
        fixes, _ = build_fixes(site, sc.detections)
        trajectories = list(run_tracker(fixes, method, roads=site.roads))
        truth_of = match_tracks(trajectories, sc.truths)
    detected = detect_all(trajectories, case.zones)
    matches = match_events(detected, truth_of, case.events)
    fired = tuple((n, _fired(n, detected, truth_of)) for n in case.near_misses)
    return CaseResult(
        activity.name,
        source,
        case.events,
        tuple(detected),
        tuple(matches),
        truth_of,
        fired,
        len(trajectories),
    )


@dataclass(frozen=True)
class DetectorScore:
    """Precision and recall of one detector over some cases.

    Attributes
    ----------
    detector : str
    n_true, n_detected : int
        True events, and detected events.
    n_found : int
        True events matched by at least one detected event.
    n_correct : int
        Detected events that match a true event.
    n_duplicates : int
        Correct detected events beyond the first for the same true event.
    near_misses, near_misses_fired : int
    """

    detector: str
    n_true: int
    n_detected: int
    n_found: int
    n_correct: int
    n_duplicates: int
    near_misses: int
    near_misses_fired: int

    @property
    def precision(self) -> float | None:
        """Correct / detected (None when nothing was detected)."""
        return self.n_correct / self.n_detected if self.n_detected else None

    @property
    def recall(self) -> float | None:
        """Found / true (None when there was nothing to find)."""
        return self.n_found / self.n_true if self.n_true else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "detector": self.detector,
            "true": self.n_true,
            "detected": self.n_detected,
            "found": self.n_found,
            "correct": self.n_correct,
            "duplicates": self.n_duplicates,
            "precision": self.precision,
            "recall": self.recall,
            "near_misses": self.near_misses,
            "near_misses_fired": self.near_misses_fired,
        }


def score_detectors(results: Sequence[CaseResult]) -> list[DetectorScore]:
    """Per detector, over all ``results``."""
    out = []
    for det in DETECTORS:
        n_true = n_det = found = correct = dup = near = fired = 0
        for r in results:
            idx = [k for k, e in enumerate(r.true_events) if detector_of(e.kind) == det]
            n_true += len(idx)
            mine = [
                m for e, m in zip(r.detected, r.matches, strict=True) if detector_of(e.kind) == det
            ]
            n_det += len(mine)
            hits = [m for m in mine if m is not None]
            correct += len(hits)
            found += len(set(hits))
            dup += len(hits) - len(set(hits))
            for n, f in r.near_misses_fired:
                if detector_of(n.kind) == det:
                    near += 1
                    fired += int(f)
        out.append(DetectorScore(det, n_true, n_det, found, correct, dup, near, fired))
    return out
