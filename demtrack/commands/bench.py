"""``demtrack bench NAME``: the benchmarks (``bench/``), one subcommand each."""

from __future__ import annotations

import argparse

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from demtrack.bench import (
        large_dem,
        lidar_holdout,
        pipeline_replay,
        raycast,
        reprocess_bench,
        server_bench,
        video_detect,
        viewshed,
    )

    jobs = {
        "raycast": raycast.main,
        "viewshed": viewshed.main,
        "server": server_bench.main,
        "pipeline": pipeline_replay.main,
        "lidar-holdout": lidar_holdout.main,
        "video": video_detect.main,
        "large-dem": large_dem.main,
        "reprocess": reprocess_bench.main,
    }
    if args.bench == "console-soak":  # Playwright is imported only for this one
        from demtrack.bench import console_soak

        jobs["console-soak"] = console_soak.main
    job = jobs[args.bench]
    return int(job(list(args.extra)) or 0)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench`` command."""
    p = sub.add_parser("bench", help="benchmarks (needs the 'bench' extra)")
    bsub = p.add_subparsers(dest="bench", metavar="NAME", required=True)
    r = bsub.add_parser("raycast", help="ray casting vs Open3D RaycastingScene", add_help=False)
    r.set_defaults(func=_run)
    v = bsub.add_parser(
        "viewshed", help="fast and exact viewshed vs GDAL's gdal_viewshed", add_help=False
    )
    v.set_defaults(func=_run)
    s = bsub.add_parser(
        "server", help="console ingest rate and WebSocket fan-out latency", add_help=False
    )
    s.set_defaults(func=_run)
    pl = bsub.add_parser(
        "pipeline",
        help="the console soak's server work in-process: CPU per detection",
        add_help=False,
    )
    pl.set_defaults(func=_run)
    lh = bsub.add_parser(
        "lidar-holdout",
        help="a sparse real lidar tile at 1 m, 10 %% held out: TIN grid vs scipy's TIN",
        add_help=False,
    )
    lh.set_defaults(func=_run)
    vd = bsub.add_parser(
        "video",
        help="demtrack watch's detection path on 1280x720 video vs OpenCV MOG2, one core",
        add_help=False,
    )
    vd.set_defaults(func=_run)
    ld = bsub.add_parser(
        "large-dem",
        help="camera rays over a tiled DEM larger than memory, under a memory budget",
        add_help=False,
    )
    ld.set_defaults(func=_run)
    rp = bsub.add_parser(
        "reprocess",
        help="archive reprocessing: local detections/s, Dask at 1, 2, 4 workers, overhead",
        add_help=False,
    )
    rp.set_defaults(func=_run)
    c = bsub.add_parser(
        "console-soak",
        help="the console in Chromium over a long replay at 10x with about 20 tracks",
        add_help=False,
    )
    c.set_defaults(func=_run)
