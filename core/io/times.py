"""Times at the edges: ISO 8601 with a zone in, UNIX seconds (UTC, float) inside, ``Z`` out.

Inside demtrack a time is ``t_s``, UNIX seconds UTC as a float64 (its resolution at
2026 is 0.24 us, far finer than any camera clock). At the edges a time is ISO 8601 with
an explicit zone (``2026-12-01T14:30:00Z``, ``2026-12-01T15:30:00+01:00``); a time
without a zone is refused, because nobody can say which clock it was read from.
Written times are UTC with a ``Z`` suffix.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta

from ..errors import TimeFormatError

__all__ = [
    "UNIX_EPOCH",
    "TimeFormatError",
    "format_utc",
    "parse_iso_time",
    "parse_time_value",
    "unix_seconds",
]

UNIX_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


def unix_seconds(when: datetime) -> float:
    """UNIX seconds (UTC) of a timezone-aware ``datetime``.

    Exact to the microsecond: the whole seconds and the microseconds are added apart, so
    no float rounding of a large ``timestamp()`` product enters.
    """
    if when.utcoffset() is None:
        raise TimeFormatError(f"time {when.isoformat()} has no zone (add Z or +hh:mm)")
    delta = when - UNIX_EPOCH
    return delta.days * 86400.0 + delta.seconds + delta.microseconds * 1e-6


def parse_iso_time(text: str, field: str = "time") -> float:
    """UNIX seconds (UTC) of an ISO 8601 time with a zone.

    Parameters
    ----------
    text : str
        ``YYYY-MM-DDTHH:MM:SS[.ffffff]`` followed by ``Z`` or ``+hh:mm`` / ``-hh:mm``
        (a space instead of ``T`` is accepted).
    field : str
        The field's name, for the message.

    Returns
    -------
    float
        UNIX seconds, UTC.

    Raises
    ------
    TimeFormatError
        When ``text`` is not ISO 8601 or has no zone (one line naming ``field``).
    """
    if not isinstance(text, str):
        raise TimeFormatError(f"{field} must be an ISO 8601 string, got {type(text).__name__}")
    s = text.strip()
    shown = s if len(s) <= 40 else s[:37] + "..."
    if len(s) < 10 or not s[:4].isdigit():
        raise TimeFormatError(f"{field} must be an ISO 8601 time with a zone, got {shown!r}")
    try:
        when = datetime.fromisoformat(s[:-1] + "+00:00" if s[-1:] in "Zz" else s)
    except ValueError:
        raise TimeFormatError(
            f"{field} must be an ISO 8601 time with a zone (e.g. 2026-12-01T14:30:00Z),"
            f" got {shown!r}"
        ) from None
    if when.utcoffset() is None:
        raise TimeFormatError(
            f"{field} {shown!r} has no zone: say which clock it is (Z for UTC, or +hh:mm)"
        )
    return unix_seconds(when)


def parse_time_value(value: object, field: str = "t") -> float:
    """UNIX seconds from a number (already UNIX seconds) or an ISO 8601 string with a zone.

    A numeric string (``"1764599400.5"``) is read as a number: query parameters arrive
    as text.
    """
    if isinstance(value, bool) or value is None:
        raise TimeFormatError(f"{field} must be UNIX seconds or an ISO 8601 time, got {value!r}")
    if isinstance(value, int | float):
        t = float(value)
    else:
        text = str(value).strip()
        try:
            t = float(text)
        except ValueError:
            return parse_iso_time(text, field)
    if not math.isfinite(t):
        raise TimeFormatError(f"{field} must be a finite number of seconds, got {value!r}")
    return t


def format_utc(t_s: float, digits: int = 3) -> str:
    """ISO 8601 UTC of UNIX seconds ``t_s``, ``Z`` suffix, ``digits`` (0-6) decimals.

    Rounded to the last digit shown (``digits=3``: milliseconds, what every export
    writes), so ``format_utc`` and :func:`parse_iso_time` round-trip to that precision.
    """
    if not math.isfinite(t_s):
        raise TimeFormatError(f"time must be finite, got {t_s!r}")
    if not 0 <= digits <= 6:
        raise TimeFormatError(f"digits must be 0 to 6, got {digits}")
    # Whole seconds and the rounded fraction apart: float64 keeps 0.24 us at 2026.
    scale = 10**digits
    whole = math.floor(t_s)
    frac = round((t_s - whole) * scale)
    if frac >= scale:
        whole, frac = whole + 1, 0
    when = UNIX_EPOCH + timedelta(seconds=whole)
    text = when.strftime("%Y-%m-%dT%H:%M:%S")
    if digits:
        text += "." + str(frac).rjust(digits, "0")
    return text + "Z"


def clock_utc(t_s: float, digits: int = 0) -> str:
    """The UTC clock time of UNIX seconds ``t_s``: ``14:32:05Z`` (``digits`` decimals).

    For a line of text where the date is known from context (a stream log line); with
    the date use :func:`format_utc`.
    """
    return format_utc(t_s, digits)[11:]
