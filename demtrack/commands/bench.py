"""``demtrack bench raycast|viewshed``: benchmarks against Open3D (Embree) and GDAL."""

from __future__ import annotations

import argparse

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from demtrack.bench import raycast, viewshed

    job = {"raycast": raycast.main, "viewshed": viewshed.main}[args.bench]
    return int(job(list(args.extra)) or 0)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench`` command."""
    p = sub.add_parser("bench", help="benchmarks (needs the 'bench' extra)")
    bsub = p.add_subparsers(dest="bench", metavar="NAME", required=True)
    r = bsub.add_parser("raycast", help="ray casting vs Open3D RaycastingScene", add_help=False)
    r.set_defaults(func=_run)
    v = bsub.add_parser("viewshed", help="exact viewshed vs GDAL's gdal_viewshed", add_help=False)
    v.set_defaults(func=_run)
