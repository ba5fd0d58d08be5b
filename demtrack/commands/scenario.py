"""``demtrack scenario``: write a sample-site scenario's detections (and its ground truth)."""

from __future__ import annotations

import argparse
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING

from demtrack.core.errors import InputFileError

from .choices import ACTIVE_LATENCY_S, SCENARIO_DEFAULTS, SCENARIO_NAMES
from .common import add_site_argument, non_negative, non_negative_int

if TYPE_CHECKING:
    from demtrack.samplesite.scenarios import ScenarioParams

__all__ = ["add_scenario_parameters", "params_from_args", "register"]


def add_scenario_parameters(p: argparse.ArgumentParser) -> None:
    """Add the detection-noise options shared by ``scenario`` and ``evaluate``."""
    d = SimpleNamespace(**SCENARIO_DEFAULTS)  # ScenarioParams' defaults, without its imports
    p.add_argument(
        "--noise-px",
        type=non_negative,
        default=d.noise_px,
        metavar="PX",
        help=f"1-sigma box-edge noise (default {d.noise_px})",
    )
    p.add_argument(
        "--p-miss",
        type=float,  # checked in _run, so a mistake is a returned status 2 like the others
        default=d.p_miss,
        metavar="P",
        help=f"missed-detection probability (default {d.p_miss})",
    )
    p.add_argument(
        "--false-alarms",
        type=non_negative,
        default=d.false_alarm_rate,
        metavar="RATE",
        help=f"mean false alarms per camera frame (default {d.false_alarm_rate})",
    )
    p.add_argument(
        "--seed", type=non_negative_int, default=d.seed, help=f"random seed (default {d.seed})"
    )


def params_from_args(args: argparse.Namespace) -> ScenarioParams:
    """The :class:`ScenarioParams` the options ask for."""
    from demtrack.samplesite.scenarios import ScenarioParams

    return ScenarioParams(
        noise_px=args.noise_px,
        p_miss=args.p_miss,
        false_alarm_rate=args.false_alarms,
        seed=args.seed,
    )


def _poses_path(out: Path, given: str | None) -> Path:
    """Where an active scenario's pose telemetry goes: ``--poses``, else beside ``out``.

    The default is the detections' name with ``.poses`` before its suffix
    (``run.jsonl`` -> ``run.poses.jsonl``), in the same format.
    """
    path = out.with_name(f"{out.stem}.poses{out.suffix}") if given is None else Path(given)
    if path.suffix.lower() not in (".csv", ".jsonl", ".ndjson"):
        raise InputFileError(f"unknown pose file type {path.suffix!r} (use .csv or .jsonl)")
    return path


def _run(args: argparse.Namespace) -> int:
    if not 0.0 <= args.p_miss <= 1.0:
        raise InputFileError(f"--p-miss must be a probability within 0..1, got {args.p_miss:g}")
    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in (".csv", ".jsonl", ".ndjson"):
        raise InputFileError(f"unknown detection file type {suffix!r} (use .csv or .jsonl)")
    from demtrack.core.io.detections import write_detections_csv, write_detections_jsonl
    from demtrack.core.io.pose_io import write_poses_csv, write_poses_jsonl
    from demtrack.core.io.times import format_utc
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.scenarios import make_scenario, write_truth_json
    from demtrack.samplesite.stamping import parse_start, stamp_scenario

    t0_s = parse_start(args.start)  # checked before the scenario is made: a quick status 2
    _poses_path(out, args.poses)  # likewise
    params = params_from_args(args)
    site = load_site(args.site)
    sc = stamp_scenario(make_scenario(site, args.name, params), t0_s)
    if suffix == ".csv":
        write_detections_csv(out, sc.detections)
    else:
        write_detections_jsonl(out, sc.detections)
    if args.truth is not None:
        write_truth_json(args.truth, sc)
    s = sc.stats
    print(
        f"{sc.name}: {len(sc.detections)} detections from {s['frames']} frames"
        f" ({s['detected']} of targets, {s['partly_hidden']} partly hidden, {s['hidden']} hidden,"
        f" {s['missed']} missed, {s['false_alarms']} false alarms) -> {out}"
    )
    if sc.poses:
        poses_path = _poses_path(out, args.poses)
        write_poses = write_poses_csv if poses_path.suffix.lower() == ".csv" else write_poses_jsonl
        write_poses(poses_path, sc.poses)
        n = sum(len(p) for p in sc.poses.values())
        print(
            f"pose telemetry: {n} samples of {len(sc.poses)} heads -> {poses_path}"
            f" (stamps {ACTIVE_LATENCY_S:g} s late, the sample sensors' pose_latency_s)"
        )
    print(f"times: UTC from {format_utc(t0_s)} (t = UNIX seconds)")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``scenario`` command."""
    p = sub.add_parser("scenario", help="simulate detections of a scenario on the sample site")
    add_site_argument(p)
    p.add_argument("--name", required=True, choices=SCENARIO_NAMES, help="scenario")
    p.add_argument(
        "-o", "--output", required=True, metavar="FILE", help="detections file (.jsonl or .csv)"
    )
    p.add_argument("--truth", metavar="FILE", help="also write the ground truth (JSON)")
    p.add_argument(
        "--poses",
        metavar="FILE",
        help="active scenarios (active-handoff): where to write the heads' pose telemetry"
        " (.csv or .jsonl; default beside the detections, NAME.poses.SUFFIX)",
    )
    p.add_argument(
        "--start",
        metavar="ISO8601",
        default="now",
        help="UTC time of the scenario's start, e.g. 2026-12-01T14:30:00Z (default now):"
        " detections and truth carry real UNIX times from it",
    )
    add_scenario_parameters(p)
    p.set_defaults(func=_run)
