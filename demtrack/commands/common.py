"""Argument helpers shared by the commands.

The ``type=`` functions (:func:`finite`, :func:`positive`, :func:`non_negative`,
:func:`probability`, :func:`positive_int`, :func:`non_negative_int`, :func:`port`) reject
a bad value while the command line is parsed, so a mistake such as ``--cell -1`` or
``--speed nan`` ends in one line and exit status 2 before any work; :mod:`demtrack.cli`
makes every ``float`` option :func:`finite` as well.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

__all__ = [
    "DEFAULT_SITE",
    "add_site_argument",
    "any_number",
    "finite",
    "non_negative",
    "non_negative_int",
    "port",
    "positive",
    "probability",
    "require_suffix",
    "positive_int",
]

#: Where ``demtrack sample-site`` and ``demtrack demo`` put the sample site by default.
DEFAULT_SITE = Path("sample_site") / "site"


def any_number(text: str) -> float:
    """A number, NaN and infinities included: for options the command checks itself.

    (``type=float`` is :func:`finite` under :mod:`demtrack.cli`.)
    """
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def finite(text: str) -> float:
    """A finite number (no NaN, no infinity)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def positive(text: str) -> float:
    """A finite number above 0."""
    value = finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def non_negative(text: str) -> float:
    """A finite number of at least 0."""
    value = finite(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {text!r}")
    return value


def probability(text: str) -> float:
    """A probability, 0 to 1."""
    value = finite(text)
    if not 0 <= value <= 1:
        raise argparse.ArgumentTypeError(f"must be a probability within 0..1, got {text!r}")
    return value


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def positive_int(text: str) -> int:
    """A whole number above 0."""
    value = _integer(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive whole number, got {text!r}")
    return value


def non_negative_int(text: str) -> int:
    """A whole number of at least 0."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number of 0 or more, got {text!r}")
    return value


def port(text: str) -> int:
    """A TCP port, 0 (any free one) to 65535."""
    value = _integer(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be within 0..65535 (a TCP port), got {text!r}")
    return value


def require_suffix(path: Path, suffixes: tuple[str, ...], option: str) -> None:
    """Refuse an output file whose suffix is not one of ``suffixes`` (before any work).

    Raises
    ------
    InputFileError
        Naming the option, the file and the suffixes it may have.
    """
    from demtrack.core.errors import InputFileError

    if path.suffix.lower() not in suffixes:
        raise InputFileError(
            f"{option} {path}: unknown file type {path.suffix or '(none)'!r}"
            f" (use {', '.join(suffixes)})"
        )


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
