"""The one exception hierarchy of the engine.

Every error a user can cause derives from :class:`DemtrackError` and from the builtin
that matches its nature, so callers may catch either. ``server/`` and the CLI map these
to HTTP statuses and one-line messages in one place each (``server/api/errors.py``:
:class:`NotFoundError` is 404, every other :class:`DemtrackError` 422).
"""

from __future__ import annotations

__all__ = [
    "CalibrationError",
    "CameraError",
    "CrsError",
    "DemError",
    "DemtrackError",
    "DetectionError",
    "GeodesyError",
    "GeoidError",
    "InputFileError",
    "NotFoundError",
    "PoseError",
    "QueryError",
    "RaycastError",
    "SettingsError",
    "SiteError",
    "TimeFormatError",
    "TrackingError",
    "UnknownSensorError",
    "VideoError",
    "VideoStallError",
]


class DemtrackError(Exception):
    """Root of every error raised on purpose by demtrack."""


class NotFoundError(DemtrackError, LookupError):
    """Something asked for by name or id that does not exist (a sensor, a track, ...)."""


class QueryError(DemtrackError, ValueError):
    """Query parameters that cannot be answered (a window ending before it starts, ...)."""


class GeodesyError(DemtrackError, ValueError):
    """Invalid geodetic input (latitude out of range, non-finite height, ...)."""


class GeoidError(DemtrackError, ValueError):
    """A geoid model that cannot be used: its grid missing or unreadable, a point off it."""


class CrsError(DemtrackError, ValueError):
    """A coordinate reference system is missing, unknown or unusable."""


class DemError(DemtrackError, ValueError):
    """An invalid elevation model or grid."""


class CameraError(DemtrackError, ValueError):
    """Invalid camera intrinsics, pose or pixel."""


class CalibrationError(DemtrackError, ValueError):
    """Calibration input that cannot give an answer (too few landmarks, ...)."""


class SiteError(DemtrackError, ValueError):
    """A site folder that is missing, incomplete or inconsistent."""


class UnknownSensorError(NotFoundError, SiteError):
    """A sensor id the site does not have (a :class:`SiteError` as well, as it always was)."""


class RaycastError(DemtrackError, ValueError):
    """Malformed ray-casting input (ray arrays, range, mode, hit limit)."""


class PoseError(CameraError):
    """An invalid sensor pose or pose series (a :class:`CameraError` as well).

    A non-finite angle, times out of order, a zoom outside the lens's calibration table.
    """


class InputFileError(DemtrackError, ValueError):
    """A malformed or unreadable input file."""


class DetectionError(DemtrackError, ValueError):
    """An invalid detection record."""


class TimeFormatError(QueryError):
    """A time that is not ISO 8601 with a zone, or not a finite number of UNIX seconds."""


class TrackingError(DemtrackError, ValueError):
    """Invalid tracker configuration or state."""


class SettingsError(DemtrackError, ValueError):
    """A server setting (a ``DEMTRACK_*`` variable or ``.env`` line) has a bad value."""


class VideoError(DemtrackError, ValueError):
    """A video that cannot be read: missing, corrupt, truncated, unreachable, no start time."""


class VideoStallError(VideoError, TimeoutError):
    """A live stream that delivered no packet within its timeout."""
