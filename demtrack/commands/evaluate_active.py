"""``demtrack evaluate`` on an active scenario: PTZ heads with telemetry, and baselines.

Also the per-method scoring helpers every scenario's ``evaluate`` shares (:func:`n_stubs`,
:func:`metrics_doc`).

The heads' detections are geolocated at the pose of each detection's moment (the
scenario's telemetry, with the site's sensors made active and ``pose_latency_s`` set),
every method is scored as on the other scenarios, and the share of the run the target was
seen by some camera (``in_view_share``) is added. Then, with the method that did best
(fewest jumps plus identity switches, then lowest RMSE):

``fixed_cameras``
    the same vehicle, the same noise, seen by the heads left at their stored pan and tilt
    (fixed cameras: less of the run in view);
``telemetry_ignored``
    the heads' detections geolocated at the stored, stale pose (what a system without
    pose telemetry would do): how wrong the fixes get, how many rays find no ground;
``latency_unknown``
    the telemetry used with its latency taken as 0 s.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from demtrack.core.site.folder import Site
    from demtrack.core.tracking import Fix, Track, TrackerConfig, TrackingMetrics, TruthPath

__all__ = [
    "STUB_S",
    "best_method",
    "fix_errors",
    "format_comparisons",
    "metrics_doc",
    "n_stubs",
    "run_active",
]

#: A track spanning less than this from first to last point is a stub (s).
STUB_S = 5.0


def n_stubs(tracks: Sequence[Track], min_s: float = STUB_S) -> int:
    """How many ``tracks`` span less than ``min_s`` seconds."""
    return sum(1 for t in tracks if t.points and t.points[-1].t_s - t.points[0].t_s < min_s)


def metrics_doc(m: TrackingMetrics, stubs: int | None = None) -> dict[str, Any]:
    """The per-method fields of ``evaluate --json`` (NaN as None)."""

    def num(x: float) -> float | None:
        return round(float(x), 4) if math.isfinite(x) else None

    doc: dict[str, Any] = {
        "rmse_m": num(m.rmse_m),
        "p95_m": num(m.p95_m),
        "jumps": m.n_jumps,
        "points": m.n_points,
        "id_switches": m.id_switches,
        "fragmentation": m.fragmentation,
        "tracks": m.n_tracks,
        "false_tracks": m.n_false_tracks,
        "coverage": num(m.coverage),
        "ospa_m": num(m.ospa_m),
        "gospa_m": num(m.gospa_m),
    }
    if stubs is not None:
        doc["stubs"] = stubs
    return doc


def best_method(scores: Sequence[tuple[str, TrackingMetrics]]) -> str:
    """The method with the fewest jumps plus identity switches, then the lowest RMSE."""

    def key(item: tuple[str, TrackingMetrics]) -> tuple[int, float]:
        m = item[1]
        rmse = m.rmse_m if math.isfinite(m.rmse_m) else math.inf
        return (m.n_jumps + m.id_switches, rmse)

    return min(scores, key=key)[0]


def fix_errors(fixes: Sequence[Fix], truths: Sequence[TruthPath]) -> dict[str, Any]:
    """Raw fixes against the truth: median error (m) and share more than 3 m off.

    Each fix's first hit against the nearest same-class target's true position at its
    time (horizontal); false alarms are included, so the median is the figure to read.
    """
    import numpy as np

    errs = []
    for fix in fixes:
        if fix.n_hits == 0:
            continue
        d = [
            float(np.linalg.norm(tr.at(fix.t_s)[0, :2] - fix.hits_enu[0, :2]))
            for tr in truths
            if tr.cls == fix.cls
        ]
        d = [x for x in d if math.isfinite(x)]
        errs.append(min(d) if d else math.inf)
    e = np.array(errs)
    if not e.size:
        return {"fix_median_error_m": None, "fixes_off_3m_share": None}
    return {
        "fix_median_error_m": round(float(np.median(e)), 3),
        "fixes_off_3m_share": round(float(np.mean(e > 3.0)), 4),
    }


def _score(fixes, site: Site, method: str, truths, config: TrackerConfig):
    from demtrack.core.tracking import evaluate, run_tracker

    roads = site.roads if method != "raw-first" else None
    tracks = run_tracker(fixes, method, roads=roads, config=config)
    return tracks, evaluate(tracks, truths), n_stubs(tracks)


def _variant(label, fixes, report, n_dets, site, method, truths, config, share) -> dict:
    _, m, stubs = _score(fixes, site, method, truths, config)
    doc = {"label": label, "method": method, **metrics_doc(m, stubs)}
    doc["in_view_share"] = None if share is None else round(share, 4)
    doc["detections"] = n_dets
    doc["fixes"] = len(fixes)
    doc["no_fix_share"] = round(1.0 - len(fixes) / n_dets, 4) if n_dets else None
    doc["skipped"] = {k: v for k, v in report.counts.items() if v}
    doc.update(fix_errors(fixes, truths))
    return doc


def _server_rows(args: argparse.Namespace, site: Site, sc: Any, batches: Sequence) -> list:
    """The live server's tracks of the heads' detections and telemetry, per batching."""
    if args.server_method == "none":
        return []
    from demtrack.core.tracking import evaluate
    from demtrack.server.ingest.offline_replay import early_ended, replay_detections

    out = []
    for speed, batch_s in batches:
        live = replay_detections(
            site, sc.detections, method=args.server_method, batch_s=batch_s, poses=sc.poses
        )
        m = evaluate(live.tracks, sc.truths)
        name = f"server {speed} ({args.server_method})"
        out.append((name, m, n_stubs(live.tracks), len(early_ended(live))))
    return out


def run_active(
    args: argparse.Namespace,
    methods: Sequence[str],
    config: TrackerConfig,
    server_batches: Sequence[tuple[str, float]] = (),
) -> dict[str, Any]:
    """Generate, geolocate, track and score an active scenario and its baselines.

    ``server_batches`` (``(label, batch_s)``) are the live server's replays to score when
    ``args.server_method`` is not ``none``: the detections and the telemetry through its
    ingest pipeline. Returns the ``--json`` document (its ``_rows`` for the table); prints
    nothing.
    """
    from dataclasses import replace

    from demtrack.core.geolocation.fix_builder import build_fixes
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.active_scenario import ActiveParams, active_site
    from demtrack.samplesite.scenarios import make_scenario

    from .scenario import params_from_args

    params = params_from_args(args)
    site = load_site(args.site)
    latency = float(args.latency)
    t0 = time.perf_counter()
    active = replace(ActiveParams(), latency_s=latency)
    sc = make_scenario(site, args.scenario, params, active=active)
    gen_s = time.perf_counter() - t0
    posed = active_site(site, latency)
    fixes, report = build_fixes(posed, sc.detections, poses=sc.poses)
    share = sc.in_view_share
    rows: list[tuple[str, TrackingMetrics, int, int | None]] = []
    doc_methods = {}
    for name in methods:
        tracks, m, stubs = _score(fixes, posed, name, sc.truths, config)
        rows.append((name, m, stubs, None))
        doc_methods[name] = {**metrics_doc(m, stubs), "in_view_share": round(share, 4)}
    best = best_method([(n, m) for n, m, _, _ in rows])
    for name, m, stubs, early in _server_rows(args, posed, sc, server_batches):
        rows.append((name, m, stubs, early))
        doc_methods[name] = {**metrics_doc(m, stubs), "in_view_share": round(share, 4)}
    n = len(sc.detections)
    active_doc = _variant(
        f"active heads (telemetry, latency {latency:g} s)",
        fixes, report, n, posed, best, sc.truths, config, share,
    )  # fmt: skip
    fixed = make_scenario(site, args.scenario, params, fixed_cameras=True)
    f_fixes, f_report = build_fixes(site, fixed.detections)
    fixed_doc = _variant(
        "fixed cameras (stored pan/tilt)", f_fixes, f_report, len(fixed.detections),
        site, best, fixed.truths, config, fixed.in_view_share,
    )  # fmt: skip
    i_fixes, i_report = build_fixes(site, sc.detections)
    ignored_doc = _variant(
        "telemetry ignored (stored pose)", i_fixes, i_report, n, site, best, sc.truths,
        config, share,
    )  # fmt: skip
    zero = active_site(site, 0.0)
    z_fixes, z_report = build_fixes(zero, sc.detections, poses=sc.poses)
    zero_doc = _variant(
        "latency unknown (0 s)", z_fixes, z_report, n, zero, best, sc.truths, config, share
    )
    return {
        "scenario": sc.name,
        "detections": n,
        "fix_report": {"fixes": report.n_fixes, "skipped": report.counts},
        "stats": sc.stats,
        "pose_latency_s": latency,
        "telemetry_samples": {sid: len(p) for sid, p in sorted(sc.poses.items())},
        "generation_s": round(gen_s, 2),
        "in_view_share": round(share, 4),
        "methods": doc_methods,
        "best_method": best,
        "comparisons": {
            "active": active_doc,
            "fixed_cameras": fixed_doc,
            "telemetry_ignored": ignored_doc,
            "latency_unknown": zero_doc,
        },
        "_rows": rows,
    }


def format_comparisons(doc: dict[str, Any]) -> str:
    """The comparison runs as a Markdown table (the best method on each)."""

    def f(x: Any, fmt: str = ".2f") -> str:
        return "-" if x is None else format(x, fmt)

    lines = [
        "| run | method | in view | RMSE (m) | p95 (m) | jumps > 3 m | ID switches"
        " | fragmentation | fixes | no fix | fix median error (m) | fixes > 3 m off |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for c in doc["comparisons"].values():
        lines.append(
            f"| {c['label']} | {c['method']} | {f(c['in_view_share'], '.1%')}"
            f" | {f(c['rmse_m'])} | {f(c['p95_m'])} | {c['jumps']} | {c['id_switches']}"
            f" | {c['fragmentation']} | {c['fixes']} | {f(c['no_fix_share'], '.1%')}"
            f" | {f(c['fix_median_error_m'])} | {f(c['fixes_off_3m_share'], '.1%')} |"
        )
    return "\n".join(lines)
