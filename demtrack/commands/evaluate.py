"""``demtrack evaluate``: run every tracking method on a scenario and score it against truth."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from demtrack.core.errors import InputFileError

from .choices import ACTIVE_LATENCY_S, ACTIVE_SCENARIO_NAMES, SCENARIO_NAMES, TRACKING_METHODS
from .common import add_site_argument
from .evaluate_active import STUB_S, metrics_doc, n_stubs
from .scenario import add_scenario_parameters, params_from_args

if TYPE_CHECKING:
    from demtrack.core.site.folder import Site
    from demtrack.core.tracking import Track, TrackerConfig, TrackingMetrics, TruthPath

__all__ = [
    "SERVER_BATCHES",
    "STUB_S",
    "format_table",
    "n_stubs",
    "plot_tracks",
    "register",
    "tracking_config",
]


def tracking_config(vehicle_coast_s: float = 4.0, human_coast_s: float = 4.0) -> TrackerConfig:
    """Tracker settings for fixed surveillance cameras with hand-off gaps.

    A track unseen for longer than ``*_coast_s`` ends (its identity is not carried
    further). Longer coasting (12 s for cars) was tried on the vehicle run: the grown gate
    then takes false alarms and the filters diverge, so the library's 4 s stays the
    default. Motion parameters are the library's.
    """
    from demtrack.core.tracking import ClassParams, TrackerConfig

    base = TrackerConfig()
    v, h = base.params("vehicle"), base.params("human")
    return TrackerConfig(
        classes={
            "vehicle": ClassParams(v.q_m2_s3, v.init_speed_sigma_m_s, vehicle_coast_s),
            "human": ClassParams(h.q_m2_s3, h.init_speed_sigma_m_s, human_coast_s),
        }
    )


#: The live server's batches in scenario seconds: the replay's 0.1 s wall-time batch
#: interval (``DEMTRACK_REPLAY_BATCH_S``) at 1x and at 10x.
SERVER_BATCHES: tuple[tuple[str, float], ...] = (("1x", 0.1), ("10x", 1.0))


def format_table(rows: Sequence[tuple[str, TrackingMetrics, int, int | None]]) -> str:
    """The metrics per method as a Markdown table.

    Each row: ``(name, metrics, stubs, ended early)``; stubs are tracks shorter than
    :data:`STUB_S`; "ended early" (the server's rows only, else None) counts tracks the
    stream announced ended that later went on.
    """
    head = (
        "| method | RMSE (m) | p95 (m) | jumps > 3 m | points | ID switches | fragmentation"
        f" | tracks (false) | stubs < {STUB_S:g} s | ended early | OSPA (m) | GOSPA (m) |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    lines = [head]
    for name, m, stubs, early in rows:
        lines.append(
            f"| {name} | {m.rmse_m:.2f} | {m.p95_m:.2f} | {m.n_jumps} | {m.n_points}"
            f" | {m.id_switches} | {m.fragmentation} | {m.n_tracks} ({m.n_false_tracks})"
            f" | {stubs} | {'-' if early is None else early}"
            f" | {m.ospa_m:.2f} | {m.gospa_m:.2f} |"
        )
    return "\n".join(lines)


def plot_tracks(
    path: str | Path,
    site: Site,
    truths: Sequence[TruthPath],
    results: Sequence[tuple[str, list[Track], TrackingMetrics]],
    title: str,
) -> None:
    """One panel per method: true paths against its tracks over the DEM hillshade (PNG)."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dem = site.dem
    z = np.nan_to_num(dem.elevation.astype(np.float64), nan=float(np.nanmean(dem.elevation)))
    g = dem.grid
    gy, gx = np.gradient(z, g.cell_m)
    gy = -gy  # row 0 is the northern row
    # Hillshade lit from the north-west, 45 degrees up.
    az, alt = math.radians(315.0), math.radians(45.0)
    slope = np.arctan(np.hypot(gx, gy))
    aspect = np.arctan2(-gx, gy)
    shade = np.sin(alt) * np.cos(slope) + np.cos(alt) * np.sin(slope) * np.cos(az - aspect)
    extent = (g.x_min, g.x_max, g.y_min, g.y_max)
    pts = np.vstack([t.p_enu[:, :2] for t in truths])
    lo, hi = pts.min(axis=0) - 15, pts.max(axis=0) + 15
    n = len(results)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.0 * rows), squeeze=False)
    colours = plt.get_cmap("tab10")
    for ax, (name, tracks, m) in zip(axes.flat, results, strict=False):
        ax.imshow(shade[::3, ::3], cmap="gray", extent=extent, origin="upper", vmin=0, vmax=1)
        for truth in truths:
            ax.plot(truth.p_enu[:, 0], truth.p_enu[:, 1], "-", color="k", lw=2.5, alpha=0.6)
        for k, track in enumerate(tracks):
            p = track.p_enu
            ax.plot(p[:, 0], p[:, 1], ".-", color=colours(k % 10), lw=0.7, ms=1.5)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_title(f"{name}: RMSE {m.rmse_m:.2f} m, {m.n_jumps} jumps", fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.suptitle(
        f"{title}: truth (black) and tracks (colour per track id); x east, y north (m)", fontsize=10
    )
    fig.tight_layout()
    fig.savefig(path, dpi=60)
    plt.close(fig)


def _run(args: argparse.Namespace) -> int:
    methods = args.methods or list(TRACKING_METHODS)
    unknown = [m for m in methods if m not in TRACKING_METHODS]
    if unknown:
        known = ", ".join(TRACKING_METHODS)
        raise InputFileError(f"unknown method(s) {', '.join(unknown)}; known: {known}")
    if not (math.isfinite(args.latency) and abs(args.latency) <= 10.0):
        raise InputFileError(f"--latency must be within -10..10 s, got {args.latency:g}")
    if args.scenario in ACTIVE_SCENARIO_NAMES:
        return _run_active(args, methods)
    from demtrack.core.geolocation.fix_builder import build_fixes
    from demtrack.core.site.folder import load_site
    from demtrack.core.tracking import evaluate, run_tracker
    from demtrack.samplesite.scenarios import make_scenario

    params = params_from_args(args)
    site = load_site(args.site)
    sc = make_scenario(site, args.scenario, params)
    fixes, report = build_fixes(site, sc.detections)
    if not args.json:
        print(f"{sc.name}: {len(sc.detections)} detections; {report.summary()}")
    config = tracking_config()
    results = []
    rows: list[tuple[str, TrackingMetrics, int, int | None]] = []
    for name in methods:
        roads = site.roads if name != "raw-first" else None
        tracks = run_tracker(fixes, name, roads=roads, config=config)
        m = evaluate(tracks, sc.truths)
        results.append((name, tracks, m))
        rows.append((name, m, n_stubs(tracks), None))
    if args.server_method != "none":
        from demtrack.server.ingest.offline_replay import early_ended, replay_detections

        for speed, batch_s in SERVER_BATCHES:
            live = replay_detections(
                site, sc.detections, method=args.server_method, batch_s=batch_s
            )
            name = f"server {speed} ({args.server_method})"
            m = evaluate(live.tracks, sc.truths)
            results.append((name, list(live.tracks), m))
            rows.append((name, m, n_stubs(live.tracks), len(early_ended(live))))
    if args.json:
        share = round(sc.in_view_share, 4)
        doc = {
            "scenario": sc.name,
            "detections": len(sc.detections),
            "fix_report": {"fixes": report.n_fixes, "skipped": report.counts},
            "in_view_share": share,
            "methods": {
                name: {**metrics_doc(m, stubs), "in_view_share": share}
                for name, m, stubs, _ in rows
            },
        }
        print(json.dumps(doc, indent=2))
    else:
        print(format_table(rows))
    if args.plot is not None:
        plot_tracks(args.plot, site, sc.truths, results, sc.name)
        if not args.json:
            print(f"plot -> {args.plot}")
    return 0


def _run_active(args: argparse.Namespace, methods: Sequence[str]) -> int:
    """An active scenario: the heads' run and its baselines (:mod:`.evaluate_active`)."""
    from .evaluate_active import format_comparisons, run_active

    doc = run_active(args, methods, tracking_config(), SERVER_BATCHES)
    rows = doc.pop("_rows")
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    rep = doc["fix_report"]
    skipped = ", ".join(f"{k}={v}" for k, v in rep["skipped"].items() if v) or "none"
    print(
        f"{doc['scenario']}: {doc['detections']} detections from moving heads"
        f" ({doc['stats']['handoffs']} hand-offs), generated in {doc['generation_s']:.1f} s;"
        f" {rep['fixes']} fixes at the telemetry's poses (latency {doc['pose_latency_s']:g} s),"
        f" skipped: {skipped}"
    )
    print(f"target in some camera's view {doc['in_view_share']:.1%} of the run")
    print(format_table(rows))
    print(f"\ncompared, with the best method ({doc['best_method']}):")
    print(format_comparisons(doc))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``evaluate`` command."""
    p = sub.add_parser("evaluate", help="score every tracking method on a scenario")
    add_site_argument(p)
    p.add_argument("--scenario", required=True, choices=SCENARIO_NAMES, help="scenario")
    p.add_argument("--methods", nargs="+", metavar="M", help="methods (default: all)")
    p.add_argument("--plot", metavar="PNG", help="write a plot of truth against tracks")
    p.add_argument(
        "--server-method",
        choices=(*TRACKING_METHODS, "none"),
        default="kalman",
        help="also score the live server's tracks: the detections through its ingest"
        " pipeline at 1x and 10x batching, with this method (default kalman, the server's;"
        " none: skip)",
    )
    p.add_argument("--json", action="store_true", help="print the scores as JSON instead of tables")
    p.add_argument(
        "--latency",
        type=float,
        default=ACTIVE_LATENCY_S,
        metavar="S",
        help="active scenarios: how late the heads' telemetry stamps are (s, default"
        f" {ACTIVE_LATENCY_S:g}); the sensors' pose_latency_s is set to it",
    )
    add_scenario_parameters(p)
    p.set_defaults(func=_run)
