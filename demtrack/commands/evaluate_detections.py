"""``demtrack evaluate-detections``: score the video detector on sample videos.

Runs the detector (:func:`demtrack.core.video.pipeline.detect_video`) on each sensor's
video, matches its detections to the video's true boxes (``FILE.truth.jsonl``, written
by ``demtrack sample-video``) and prints precision, recall and mean IoU at IoU 0.5, class
accuracy and the foot-pixel error in pixels and on the ground
(:mod:`demtrack.samplesite.video_eval`). Then every tracking method of ``demtrack track``
runs on the video's detections of all the sensors given, and on the true boxes as
detections, and both are scored against the scenario's true paths side by side.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from .choices import SCENARIO_NAMES, TRACKING_METHODS
from .common import add_site_argument

__all__ = ["BAR", "register"]

#: The issue's bar: precision, recall, class accuracy, RMSE gap (m), identity switches.
BAR = {"precision": 0.9, "recall": 0.9, "class_accuracy": 0.95, "rmse_gap_m": 0.3, "id_switches": 0}


def _masks(items: list[str] | None, sensors: list[str]) -> dict[str, Path]:
    """``--mask ID=FILE.png`` options as sensor -> mask file."""
    from demtrack.core.errors import InputFileError

    out = {}
    for item in items or ():
        sensor, sep, path = item.partition("=")
        if not sep or not path:
            raise InputFileError(f"--mask {item}: give ID=FILE.png")
        if sensor not in sensors:
            raise InputFileError(f"--mask {item}: {sensor} is not one of the --sensor ids")
        if not Path(path).is_file():
            raise InputFileError(f"--mask {item}: no such file")
        out[sensor] = Path(path)
    return out


def _detect(
    site: Any, sensor: str, video: Path, detector: str, mask: Path | None = None
) -> tuple[list, float]:
    from demtrack.core.video.pipeline import detect_video

    clock = time.perf_counter()
    dets = list(detect_video(site, sensor, str(video), detector=detector, mask=mask))
    return dets, time.perf_counter() - clock


def _read_saved(path: Path, sensor: str) -> list:
    """A saved detections file's records of ``sensor`` (``demtrack watch``'s JSON Lines)."""
    from demtrack.core.io.detections import read_detections

    dets, _ = read_detections(path)
    return [d for d in dets if d.sensor == sensor]


def _fmt(x: float, digits: int = 3) -> str:
    return "-" if not math.isfinite(x) else f"{x:.{digits}f}"


def _tracking(site: Any, video_dets: list, box_dets: list, truths: list) -> list[dict]:
    """Every method on both detection sets: one row per method."""
    from demtrack.core.geolocation.fix_builder import build_fixes
    from demtrack.core.tracking import evaluate, run_tracker

    from .evaluate import tracking_config

    config = tracking_config()
    rows = []
    fixes = {
        "video": build_fixes(site, sorted(video_dets, key=lambda d: d.t_s))[0],
        "boxes": build_fixes(site, sorted(box_dets, key=lambda d: d.t_s))[0],
    }
    for method in TRACKING_METHODS:
        roads = site.roads if method != "raw-first" else None
        row: dict[str, Any] = {"method": method}
        for key, fx in fixes.items():
            m = evaluate(run_tracker(fx, method, roads=roads, config=config), truths)
            row[key] = {
                "rmse_m": round(m.rmse_m, 3),
                "jumps": m.n_jumps,
                "id_switches": m.id_switches,
                "tracks": m.n_tracks,
                "false_tracks": m.n_false_tracks,
            }
        rows.append(row)
    return rows


def _verdict(pooled: dict, rows: list[dict]) -> tuple[dict, list[str]]:
    """The best method from video, and what misses the bar."""
    finite = [r for r in rows if math.isfinite(r["video"]["rmse_m"])]
    best = min(finite, key=lambda r: r["video"]["rmse_m"]) if finite else rows[0]
    fails = [
        f"{k} {pooled[k]:.3f} < {BAR[k]}"
        for k in ("precision", "recall", "class_accuracy")
        if not pooled[k] >= BAR[k]
    ]
    gap = best["video"]["rmse_m"] - best["boxes"]["rmse_m"]
    if not gap <= BAR["rmse_gap_m"]:
        fails.append(f"{best['method']}: RMSE from video {gap:+.2f} m of the true boxes' (> 0.3)")
    if best["video"]["id_switches"] > BAR["id_switches"]:
        fails.append(f"{best['method']}: {best['video']['id_switches']} identity switches")
    return best, fails


def _run(args: argparse.Namespace) -> int:
    from demtrack.core.errors import InputFileError

    sensors, videos = args.sensor, [Path(v) for v in args.video]
    if len(sensors) != len(videos):
        raise InputFileError(
            f"give one --video per --sensor, in the same order ({len(sensors)} sensors,"
            f" {len(videos)} videos)"
        )
    saved = [Path(p) for p in args.detections or ()]
    if saved and len(saved) != len(sensors):
        raise InputFileError(
            f"give one --detections per --sensor, in the same order ({len(sensors)} sensors,"
            f" {len(saved)} detection files)"
        )
    masks = _masks(args.mask, sensors)
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.scenarios import make_scenario
    from demtrack.samplesite.video_eval import (
        DetectionScores,
        score_detections,
        scored_from,
        truth_detections,
    )
    from demtrack.samplesite.video_file import read_video_truth, truth_path_for

    truths_by_video = []
    for sensor, video in zip(sensors, videos, strict=True):
        if not video.is_file():
            raise InputFileError(f"--video {video}: no such file")
        vt = read_video_truth(truth_path_for(video))
        if vt.sensor != sensor or vt.header["scenario"] != args.scenario:
            raise InputFileError(
                f"--video {video} is {vt.header['scenario']} from {vt.sensor}, not"
                f" {args.scenario} from {sensor}"
            )
        truths_by_video.append(vt)
    site = load_site(args.site)
    scores, video_dets, box_dets, speed = [], [], [], []
    for k, (sensor, video, vt) in enumerate(zip(sensors, videos, truths_by_video, strict=True)):
        if saved:
            dets = _read_saved(saved[k], sensor)
        else:
            dets, seconds = _detect(site, sensor, video, args.detector, masks.get(sensor))
            speed.append((sensor, len(vt.frames) / seconds if seconds > 0 else math.inf))
        scores.append(score_detections(site, dets, vt, score_from_s=args.score_from))
        t_scored = scored_from(vt, args.score_from)
        video_dets += [d for d in dets if d.t_s >= t_scored]
        box_dets += truth_detections(vt)
    start_s = truths_by_video[0].start_s
    sc = make_scenario(site, args.scenario)
    from demtrack.core.tracking.types import TruthPath

    paths = [TruthPath(t.target_id, t.cls, t.t_s + start_s, t.p_enu) for t in sc.truths]
    rows = _tracking(site, video_dets, box_dets, paths)
    per_sensor = [s.summary() for s in scores]
    pooled = DetectionScores.pooled(scores).summary()
    best, fails = _verdict(pooled, rows)
    doc = {
        "scenario": args.scenario,
        "detector": "saved detections" if saved else args.detector,
        "scored_from_s": args.score_from,
        "detection": per_sensor + ([pooled] if len(scores) > 1 else []),
        "detector_frames_per_s": {s: round(f, 1) for s, f in speed},
        "tracking": rows,
        "best_method": best["method"],
        "bar_failures": fails,
    }
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(
        f"{args.scenario}, detector {doc['detector']}: detection at IoU 0.5"
        " (foot error: median / p95)\n"
        "| sensor | true boxes | detections | precision | recall | mean IoU | class acc."
        " | foot px | foot m | frames/s |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    fps = dict(speed)
    for s in doc["detection"]:
        print(
            f"| {s['sensor']} | {s['truth_boxes']} | {s['detections']} | {_fmt(s['precision'])}"
            f" | {_fmt(s['recall'])} | {_fmt(s['mean_iou'])} | {_fmt(s['class_accuracy'])}"
            f" | {_fmt(s['foot_px_median'], 1)} / {_fmt(s['foot_px_p95'], 1)}"
            f" | {_fmt(s['foot_m_median'], 2)} / {_fmt(s['foot_m_p95'], 2)}"
            f" | {_fmt(fps.get(s['sensor'], math.nan), 1)} |"
        )
    print(
        f"\ntracking ({', '.join(sensors)}): from the video's detections | from the true boxes\n"
        "| method | RMSE (m) | jumps > 3 m | ID switches | tracks (false) | RMSE (m) | jumps"
        " | ID switches | tracks (false) |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    for r in rows:
        cells = []
        for key in ("video", "boxes"):
            m = r[key]
            cells += [
                _fmt(m["rmse_m"], 2),
                str(m["jumps"]),
                str(m["id_switches"]),
                f"{m['tracks']} ({m['false_tracks']})",
            ]
        print(f"| {r['method']} | " + " | ".join(cells) + " |")
    print(
        "\nrecall by true box height: "
        + "; ".join(
            f"{s['sensor']} " + ", ".join(f"{k} {v:.2f}" for k, v in s["recall_by_height"].items())
            for s in doc["detection"]
        )
    )
    verdict = "meets the bar" if not fails else "misses the bar: " + "; ".join(fails)
    print(f"\nbest method from video: {best['method']}; {verdict}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``evaluate-detections`` command."""
    p = sub.add_parser(
        "evaluate-detections", help="score the video detector on sample videos against truth"
    )
    add_site_argument(p)
    p.add_argument("--scenario", required=True, choices=SCENARIO_NAMES, help="scenario")
    p.add_argument(
        "--sensor", required=True, action="append", metavar="ID", help="camera (repeatable)"
    )
    p.add_argument(
        "--video",
        required=True,
        action="append",
        metavar="FILE.mp4",
        help="its sample video, FILE.truth.jsonl beside it (repeatable, in --sensor order)",
    )
    p.add_argument(
        "--detector", choices=("vsam", "mog2", "knn"), default="vsam", help="default vsam"
    )
    p.add_argument(
        "--detections",
        action="append",
        metavar="FILE",
        help="score these saved detections (CSV or JSON Lines, e.g. from demtrack watch)"
        " instead of running the detector (repeatable, in --sensor order)",
    )
    p.add_argument(
        "--mask",
        action="append",
        metavar="ID=FILE.png",
        help="the detector's mask for a sensor (white = ignore, e.g. trees in wind; repeatable)",
    )
    p.add_argument(
        "--score-from",
        type=float,
        metavar="S",
        help="score (and track) from this scenario time (s; default: the first motion, after"
        " the video's lead-in in which the detector learns the scene)",
    )
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=_run)
