"""``demtrack bench raycast|viewshed|server``: benchmarks (Open3D/Embree, GDAL, the server)."""

from __future__ import annotations

import argparse

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from demtrack.bench import raycast, server_bench, viewshed

    job = {"raycast": raycast.main, "viewshed": viewshed.main, "server": server_bench.main}[
        args.bench
    ]
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
