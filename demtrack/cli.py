"""Command-line entry point: ``demtrack <command> ...``.

Each command lives in its own module under :mod:`demtrack.commands` and exposes
``register(subparsers)``, which adds its parser and sets ``func``. User mistakes
(:class:`~demtrack.core.errors.DemtrackError`, missing files) end in one line on stderr
and exit status 2; nothing prints a traceback for them.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from demtrack.commands import COMMANDS
from demtrack.commands.common import finite
from demtrack.core.errors import DemtrackError

__all__ = ["build_parser", "console_main", "main"]

EXIT_USER_ERROR = 2


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors, and every ``type=float`` option finite.

    The subcommands' parsers are of this class too (``add_subparsers`` uses the parent's).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.register("type", float, finite)  # NaN and infinities are mistakes everywhere

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` as one line and exit with status 2."""
        message = re.sub(r"^argument ([^:]+): ", r"\1 ", message)  # "--speed must be ..."
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every command registered."""
    parser = _Parser(
        prog="demtrack",
        description="Geolocate and track people and vehicles from calibrated cameras and a DEM.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMANDS:
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns the process exit status."""
    parser = build_parser()
    # Benchmarks parse their own options: pass what the CLI does not know through to them.
    args, extra = parser.parse_known_args(argv)
    if extra and args.command != "bench":
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.extra = extra
    try:
        return int(args.func(args) or 0)
    except DemtrackError as exc:
        print(f"demtrack {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as exc:  # a missing, unreadable or unwritable file, a full disk
        if exc.strerror and exc.filename:
            what = f"{exc.strerror}: {exc.filename}"
        else:
            what = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"demtrack {args.command}: error: {what}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print(f"demtrack {args.command}: interrupted", file=sys.stderr)
        return 130


def console_main() -> None:
    """Console-script entry: exit with :func:`main`'s status."""
    sys.exit(main())


if __name__ == "__main__":
    console_main()
