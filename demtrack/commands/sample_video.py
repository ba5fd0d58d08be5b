"""``demtrack sample-video``: render what a sample camera sees during a scenario (MP4).

The draped terrain, the targets as shaded boxes hidden by the DEM's crowns and roofs,
swaying crowns, illumination drift and sensor noise (:mod:`demtrack.samplesite.video_render`);
the true boxes go to ``FILE.truth.jsonl`` beside the video (:mod:`demtrack.samplesite.video_file`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .choices import SCENARIO_NAMES
from .common import add_site_argument, non_negative, non_negative_int, positive, require_suffix

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    require_suffix(Path(args.output), (".mp4",), "-o")
    from demtrack.core.errors import InputFileError
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.stamping import parse_start
    from demtrack.samplesite.video_file import write_sample_video
    from demtrack.samplesite.video_render import RenderLook

    start_s = parse_start(args.start)
    if args.t_from is not None and args.t_to is not None and args.t_to < args.t_from:
        raise InputFileError(f"--t-to {args.t_to:g} is before --t-from {args.t_from:g}")
    site = load_site(args.site)
    look = RenderLook(noise_sigma=args.noise, drift=args.drift, sway=args.sway)
    report = write_sample_video(
        site,
        args.scenario,
        args.sensor,
        args.output,
        start_s=start_s,
        t_from_s=args.t_from,
        t_to_s=args.t_to,
        seed=args.seed,
        rate_hz=args.rate,
        look=look,
        log=print,
    )
    print(
        f"{args.scenario}, {args.sensor}: {report.frames} frames, {report.boxes} counted true"
        f" boxes, {report.frames_per_s:.1f} frames/s rendered and encoded -> {report.video}"
    )
    print(f"true boxes -> {report.truth}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sample-video`` command."""
    p = sub.add_parser(
        "sample-video", help="render a sample camera's video of a scenario, with its true boxes"
    )
    add_site_argument(p)
    p.add_argument("--scenario", required=True, choices=SCENARIO_NAMES, help="scenario")
    p.add_argument("--sensor", required=True, metavar="ID", help="camera id, e.g. cam1")
    p.add_argument("-o", "--output", required=True, metavar="FILE.mp4", help="video to write")
    p.add_argument(
        "--start",
        metavar="ISO8601",
        default="now",
        help="UTC time of the scenario's t = 0 (default now); the video's creation_time and"
        " frame timestamps follow from it",
    )
    p.add_argument(
        "--seed", type=non_negative_int, default=0, help="seed of noise, sway, drift (default 0)"
    )
    p.add_argument(
        "--t-from",
        type=float,
        metavar="S",
        help="first frame, scenario seconds (default 15 s before the first target moves)",
    )
    p.add_argument("--t-to", type=float, metavar="S", help="last frame (default: the end)")
    p.add_argument("--rate", type=positive, metavar="HZ", help="frame rate (default 10)")
    p.add_argument(
        "--noise", type=non_negative, default=2.0, metavar="DN", help="sensor noise (default 2)"
    )
    p.add_argument(
        "--drift",
        type=non_negative,
        default=0.05,
        metavar="F",
        help="illumination drift amplitude, a fraction (default 0.05)",
    )
    p.add_argument(
        "--sway",
        type=non_negative,
        default=1.0,
        metavar="F",
        help="scale of the tree crowns' sway (default 1: 0.3 m)",
    )
    p.set_defaults(func=_run)
