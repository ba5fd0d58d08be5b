"""``demtrack bench raycast``: the ray-casting benchmark against Open3D (Embree)."""

from __future__ import annotations

import argparse

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from demtrack.bench import raycast

    return int(raycast.main(args.rest) or 0)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench`` command."""
    p = sub.add_parser("bench", help="benchmarks (needs the 'bench' extra)")
    bsub = p.add_subparsers(dest="bench", metavar="NAME", required=True)
    r = bsub.add_parser("raycast", help="ray casting vs Open3D RaycastingScene", add_help=False)
    r.add_argument("rest", nargs=argparse.REMAINDER)
    r.set_defaults(func=_run)
