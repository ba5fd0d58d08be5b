"""Dense-traffic tracking, ground-truthed: the console soak's staggered copies, offline.

The console soak (:mod:`.console_soak`) replays the three sample-site scenarios as several
copies each, staggered over each scenario's period (:func:`demtrack.server.replay.scenario_stream`):
copy ``k`` is made with noise seed ``k`` and starts ``k / copies`` of the period (span plus
the loop gap) after copy 0, rounded to a whole frame. The copies are the *same* objects on
the *same* paths a fraction of a period apart, so a lost track of one copy has a twin of
another copy coming along its road some seconds later: the hard case for re-acquisition.

This builds that scene with its truth (each copy's and each loop's targets shifted by the
same time, with ids of their own), tracks it with the batch entry point, and scores it:

- :func:`demtrack.core.tracking.evaluate`: RMSE, points off by more than 3 m, identity
  switches, fragmentation;
- **wrong joins**: a track's gaps (:attr:`Track.gaps`, intervals without points longer
  than the tracker's gap threshold: coasting bridged, or a lost track re-acquired): the
  five points either side of a gap are matched to the same-class target they are
  closest to (median, within 5 m); a gap whose two sides are matched to different
  targets joined two objects (a gap with an unmatched side is counted apart);
- **re-acquisitions**: gaps longer than the coasting limit (4 s), which only the
  re-acquisition bridges; wrong when the sides are different targets or one is near none;
- **jumpy tracks**: tracks with consecutive points farther apart than a plausible motion
  (``max(5 m, v_max * dt)``, ``v_max`` 30 m/s for vehicles, 4 m/s for people);
- **ghost triangulations** (:func:`fused_ghosts`): two-camera points far from every object.

Run: ``python -m demtrack.bench.dense_tracking [--site DIR] [--copies 4] [--loops 1]
[--methods kalman ...]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from demtrack.core.site.folder import Site
    from demtrack.core.tracking import Fix, Track, TrackingMetrics, TruthPath
    from demtrack.core.tracking.protocols import Measurement
    from demtrack.core.tracking.types import Detection
    from demtrack.server.scenario_source import ScenarioSource

__all__ = [
    "SCENARIOS",
    "V_MAX_M_S",
    "DenseScene",
    "DenseScore",
    "dense_scene",
    "fused_ghosts",
    "jump_pairs",
    "main",
    "score_dense",
    "gap_targets",
    "track_dense",
    "wrong_joins",
]

SCENARIOS = ("vehicle-run", "pedestrians", "passing-vehicles")

#: Fastest plausible motion per class (m/s) for :func:`jump_pairs`.
V_MAX_M_S = {"vehicle": 30.0, "human": 4.0}


@dataclass(frozen=True, eq=False)
class DenseScene:
    """Staggered scenario copies with their truth.

    Parameters
    ----------
    detections : list of Detection
        All copies' detections, time-shifted, in time order (then sensor).
    truths : list of TruthPath
        One per (scenario, copy, loop, target), ids ``0..``, shifted like its detections.
    labels : dict of int to str
        Truth id -> ``"scenario/copy/loop/target"``.
    """

    detections: list[Detection]
    truths: list[TruthPath]
    labels: dict[int, str]


def dense_scene(
    site: Site,
    names: Sequence[str] = SCENARIOS,
    *,
    copies: int = 4,
    loops: int = 1,
    gap_s: float | None = None,
    rate_hz: float | None = None,
    source: ScenarioSource | None = None,
) -> DenseScene:
    """The scene :func:`~demtrack.server.replay.scenario_stream` replays from time 0.

    ``source`` makes the scenarios (default: the sample site's,
    :data:`~demtrack.samplesite.replay_source.SAMPLE_SCENARIOS`).

    Copy ``k`` of a scenario has noise seed ``k``; loop periods and start offsets come
    from :func:`~demtrack.server.replay_schedule.replay_schedule` (``gap_s`` default:
    the replay's loop gap), as the replay does: copy ``k`` of scenario ``j``, loop ``l``
    is shifted by ``offsets[j][k] + l * periods[j]``.
    """
    from demtrack.core.tracking import TruthPath
    from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS
    from demtrack.server.replay import LOOP_GAP_S, scenario_copies
    from demtrack.server.replay_schedule import replay_schedule

    gap = LOOP_GAP_S if gap_s is None else float(gap_s)
    dets: list[Detection] = []
    truths: list[TruthPath] = []
    labels: dict[int, str] = {}
    made_all, rate = scenario_copies(
        site, names, copies, rate_hz, source=SAMPLE_SCENARIOS if source is None else source
    )
    played = [(name, made) for name, made in made_all if made[0].detections]
    periods, offsets = replay_schedule(
        [max(d.t_s for d in made[0].detections) for _, made in played],
        [made[0].truths for _, made in played],
        copies,
        rate,
        gap,
    )
    for j, (name, made) in enumerate(played):
        for k, sc in enumerate(made):
            for loop in range(loops):
                shift = offsets[j][k] + loop * periods[j]
                dets += [dataclasses.replace(d, t_s=round(d.t_s + shift, 6)) for d in sc.detections]
                for tr in sc.truths:
                    tid = len(truths)
                    truths.append(TruthPath(tid, tr.cls, tr.t_s + shift, tr.p_enu))
                    labels[tid] = f"{name}/{k}/{loop}/{tr.target_id}"
    dets.sort(key=lambda d: (d.t_s, d.sensor))
    return DenseScene(dets, truths, labels)


def _nearest_target(
    track: Track, idx: np.ndarray, truths: Sequence[TruthPath], match_threshold_m: float
) -> int | None:
    """Same-class target with the smallest median error over points ``idx`` (or None)."""
    xy = track.p_enu[idx, :2]
    best, best_err = None, np.inf
    for truth in truths:
        if truth.cls != track.cls:
            continue
        err = np.linalg.norm(xy - truth.at(track.t_s[idx])[:, :2], axis=1)
        err = err[np.isfinite(err)]
        if err.size and float(np.median(err)) < best_err:
            best, best_err = truth.target_id, float(np.median(err))
    return best if best_err <= match_threshold_m else None


def gap_targets(
    track: Track,
    truths: Sequence[TruthPath],
    match_threshold_m: float = 5.0,
    n_points: int = 5,
) -> list[tuple[int | None, int | None]]:
    """Targets matched just before and just after each of ``track``'s gaps.

    Each side is the ``n_points`` points next to the gap (fewer where the track has
    fewer before the previous gap or after the next one), matched to the same-class
    target with the smallest median horizontal error within ``match_threshold_m``.
    """
    t = track.t_s
    cuts = [0, *(int(np.searchsorted(t, b, side="left")) for _, b in track.gaps), t.size]
    out = []
    for g in range(len(track.gaps)):
        lo, mid, hi = cuts[g], cuts[g + 1], cuts[g + 2]
        before = np.arange(max(lo, mid - n_points), mid)
        after = np.arange(mid, min(hi, mid + n_points))
        out.append(
            (
                _nearest_target(track, before, truths, match_threshold_m),
                _nearest_target(track, after, truths, match_threshold_m),
            )
        )
    return out


def wrong_joins(
    tracks: Sequence[Track], truths: Sequence[TruthPath], match_threshold_m: float = 5.0
) -> tuple[list[tuple[int, float, float, int, int]], int]:
    """Gaps whose two sides are different targets (:func:`gap_targets`).

    Returns
    -------
    joins : list of (track id, gap start s, gap end s, target before, target after)
        Gaps joining two different matched targets.
    n_unmatched : int
        Gaps with a side matched to no target (a false or badly off piece of track).
    """
    joins = []
    n_unmatched = 0
    for track in tracks:
        if not track.gaps:
            continue
        sides = gap_targets(track, truths, match_threshold_m)
        for (a, b), (before, after) in zip(track.gaps, sides, strict=True):
            if before is None or after is None:
                n_unmatched += 1
            elif before != after:
                joins.append((track.id, a, b, before, after))
    return joins, n_unmatched


def fused_ghosts(
    fixes: Sequence[Fix],
    truths: Sequence[TruthPath],
    fuse: Callable[..., list[Measurement]] | None = None,
    threshold_m: float = 4.0,
) -> tuple[int, int]:
    """Two-camera triangulations made of ``fixes`` and those off every object.

    The fixes are grouped into steps as the tracker groups them (``step_window_s``) and
    fused (default :func:`demtrack.core.tracking.fusion.fuse_measurements`). Returns
    ``(n_fused, n_ghosts)``: a ghost is a triangulated point farther than
    ``threshold_m`` from every same-class target's true position at its time.
    """
    from demtrack.core.tracking import TrackerConfig
    from demtrack.core.tracking.fusion import fuse_measurements
    from demtrack.core.tracking.protocols import Measurement

    config = TrackerConfig()
    fuse = fuse_measurements if fuse is None else fuse
    order = sorted(range(len(fixes)), key=lambda i: fixes[i].t_s)
    steps: list[list[int]] = []
    for i in order:
        if steps and fixes[i].t_s - fixes[steps[-1][0]].t_s <= config.step_window_s:
            steps[-1].append(i)
        else:
            steps.append([i])
    n_fused = n_ghosts = 0
    for step in steps:
        if len(step) < 2:
            continue
        meas = [Measurement(fixes[i], (i,), (fixes[i].sensor,)) for i in step]
        for m in fuse(meas, config):
            if len(m.sensors) < 2:
                continue
            n_fused += 1
            p = m.fix.hits_enu[0, :2]
            d = [float(np.linalg.norm(tr.at(m.t_s)[0, :2] - p)) for tr in truths if tr.cls == m.cls]
            d = [x for x in d if np.isfinite(x)]
            n_ghosts += int(not d or min(d) > threshold_m)
    return n_fused, n_ghosts


def jump_pairs(track: Track, floor_m: float = 5.0) -> int:
    """Consecutive point pairs of ``track`` farther apart than plausible motion allows."""
    t, xy = track.t_s, track.p_enu[:, :2]
    if t.size < 2:
        return 0
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    limit = np.maximum(floor_m, V_MAX_M_S.get(track.cls, 30.0) * np.diff(t))
    return int(np.sum(step > limit))


@dataclass(frozen=True)
class DenseScore:
    """Scores of one method on a dense scene (see the module docstring)."""

    metrics: TrackingMetrics
    n_gaps: int
    wrong_joins: tuple[tuple[int, float, float, int, int], ...]
    n_unmatched_gaps: int
    n_jumpy_tracks: int
    n_jump_pairs: int
    n_reacquired: int
    n_wrong_reacquired: int


def score_dense(
    tracks: Sequence[Track], truths: Sequence[TruthPath], max_coast_s: float = 4.0
) -> DenseScore:
    """Score ``tracks`` of a dense scene against its truth.

    A gap longer than ``max_coast_s`` (the tracker's coasting limit) is a re-acquisition;
    it is wrong when its sides are different targets or one side is near none.
    """
    from demtrack.core.tracking import evaluate

    joins, unmatched = wrong_joins(tracks, truths)
    pairs = [jump_pairs(t) for t in tracks]
    n_re = n_wrong = 0
    for track in tracks:
        if not any(b - a > max_coast_s for a, b in track.gaps):
            continue
        for (a, b), (before, after) in zip(track.gaps, gap_targets(track, truths), strict=True):
            if b - a > max_coast_s:
                n_re += 1
                n_wrong += int(before is None or before != after)
    return DenseScore(
        metrics=evaluate(tracks, truths),
        n_gaps=sum(len(t.gaps) for t in tracks),
        wrong_joins=tuple(joins),
        n_unmatched_gaps=unmatched,
        n_jumpy_tracks=sum(1 for p in pairs if p),
        n_jump_pairs=sum(pairs),
        n_reacquired=n_re,
        n_wrong_reacquired=n_wrong,
    )


def track_dense(site: Site, fixes: Sequence[Fix], method: str) -> list[Track]:
    """Track ``fixes`` as the server does: the method's library defaults, the site's roads."""
    from demtrack.core.tracking import run_tracker

    return run_tracker(fixes, method, roads=site.roads)


def main(argv: Sequence[str] | None = None) -> int:
    """Build the dense scene, track it with each method and print the scores."""
    from demtrack.core.geolocation.fix_builder import build_fixes
    from demtrack.core.site.folder import load_site

    p = argparse.ArgumentParser(prog="dense_tracking", description=__doc__.split("\n")[0])
    p.add_argument("--site", default="/tmp/site", help="a built sample site")
    p.add_argument("--copies", type=int, default=4)
    p.add_argument("--loops", type=int, default=1)
    p.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    p.add_argument("--methods", nargs="+", default=["kalman"])
    p.add_argument("--verbose", action="store_true", help="list every wrong join")
    args = p.parse_args(argv)
    site = load_site(args.site)
    scene = dense_scene(site, args.scenarios, copies=args.copies, loops=args.loops)
    fixes, _ = build_fixes(site, scene.detections)
    print(
        f"{len(scene.detections)} detections, {len(fixes)} fixes, {len(scene.truths)} targets"
        f" ({args.copies} copies x {args.loops} loops of {', '.join(args.scenarios)})"
    )
    n_fused, n_ghosts = fused_ghosts(fixes, scene.truths)
    print(f"two-camera triangulations: {n_fused}, ghosts (> 4 m from every object): {n_ghosts}")
    print(
        "| method | tracks (false) | RMSE (m) | points > 3 m | ID switches | fragmentation"
        " | gaps | wrong joins | gaps to no target | re-acquisitions (wrong)"
        " | jumpy tracks (pairs) | CPU s |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for method in args.methods:
        c0 = time.process_time()
        tracks = track_dense(site, fixes, method)
        cpu = time.process_time() - c0
        s = score_dense(tracks, scene.truths)
        m = s.metrics
        print(
            f"| {method} | {m.n_tracks} ({m.n_false_tracks}) | {m.rmse_m:.2f} | {m.n_jumps}"
            f" | {m.id_switches} | {m.fragmentation} | {s.n_gaps} | {len(s.wrong_joins)}"
            f" | {s.n_unmatched_gaps} | {s.n_reacquired} ({s.n_wrong_reacquired})"
            f" | {s.n_jumpy_tracks} ({s.n_jump_pairs}) | {cpu:.1f} |"
        )
        if args.verbose:
            for tid, a, b, before, after in s.wrong_joins:
                print(
                    f"  track {tid}: gap {a:.1f}-{b:.1f} s joins"
                    f" {scene.labels[before]} -> {scene.labels[after]}"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
