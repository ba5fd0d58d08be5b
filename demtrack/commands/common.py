"""Argument helpers shared by the commands."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["DEFAULT_SITE", "add_site_argument"]

#: Where ``demtrack sample-site`` and ``demtrack demo`` put the sample site by default.
DEFAULT_SITE = Path("sample_site") / "site"


def add_site_argument(parser: argparse.ArgumentParser, required: bool = False) -> None:
    """Add ``--site DIR`` (default: the generated sample site)."""
    parser.add_argument(
        "--site",
        type=Path,
        default=None if required else DEFAULT_SITE,
        required=required,
        metavar="DIR",
        help=f"site folder (default: {DEFAULT_SITE})",
    )
