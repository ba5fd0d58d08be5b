"""The one exception hierarchy of the engine.

Every error a user can cause derives from :class:`DemtrackError` and from the builtin
that matches its nature, so callers may catch either. ``server/`` and the CLI map these
to HTTP statuses and one-line messages in one place each.
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
    "InputFileError",
    "RaycastError",
    "SiteError",
    "TrackingError",
]


class DemtrackError(Exception):
    """Root of every error raised on purpose by demtrack."""


class GeodesyError(DemtrackError, ValueError):
    """Invalid geodetic input (latitude out of range, non-finite height, ...)."""


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


class RaycastError(DemtrackError, ValueError):
    """Malformed ray-casting input (ray arrays, range, mode, hit limit)."""


class InputFileError(DemtrackError, ValueError):
    """A malformed or unreadable input file."""


class DetectionError(DemtrackError, ValueError):
    """An invalid detection record."""


class TrackingError(DemtrackError, ValueError):
    """Invalid tracker configuration or state."""
