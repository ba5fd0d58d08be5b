"""What every track export shares: heights, times and the runs between gaps.

A track is prepared once (:func:`prepare_tracks`) into an :class:`ExportTrack`: WGS84
``lat/lon``, the ellipsoidal height ``h`` (GeoJSON's third coordinate, GeoPackage z), the
*absolute* height the sea-level formats want (KML ``absolute``, GPX ``<ele>``), each
point's ISO 8601 UTC time, and the point indices of its runs between gaps (each run is
written as its own segment, never a straight line across the gap).

Heights follow a :class:`HeightModel`, normally built from the site's
:class:`~demtrack.core.geo.geoid.GeoidModel` (:meth:`HeightModel.from_geoid`): with a
geoid the absolute height is the orthometric ``H = h - N(lat, lon)``, ``N`` evaluated at
each point (EGM96 from its 15' grid, a national grid, or a stated constant); without one
it is the ellipsoidal ``h``, and every file says so (:attr:`HeightModel.note`,
:attr:`HeightModel.datum_name`).

Times follow a :class:`TimeBase`: a point's time is ``epoch + t_s``. demtrack's ``t_s``
are UNIX seconds UTC, so the epoch is 1970-01-01T00:00:00Z and the times are real UTC
clock times (``wall_clock``). Only for session seconds (an old store, a file without an
epoch whose times are all before 2000: :meth:`TimeBase.for_times`) is the epoch merely
declared, and then every file says the times are relative to it.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from ..errors import GeoidError, TrackingError
from ..geo.geoid import GeoidModel
from ..tracking.types import Track

__all__ = [
    "UNIX_EPOCH",
    "ExportTrack",
    "HeightModel",
    "OrthometricFn",
    "TimeBase",
    "ToGeodetic",
    "iso_utc",
    "prepare_tracks",
    "split_at_gaps",
]

#: ``(e_m, n_m, u_m) -> (lat_deg, lon_deg, h_m)``, h above the WGS84 ellipsoid.
ToGeodetic = Callable[[float, float, float], tuple[float, float, float]]
#: ``(lat_deg, lon_deg, h_m) -> H_m``: arrays of shape (n,) in, orthometric heights out.
OrthometricFn = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
UNIX_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
#: UNIX seconds of 2000-01-01T00:00:00Z: times all before it are session seconds.
_RELATIVE_BEFORE_S = 946684800.0


def _check_epoch(epoch: datetime | None) -> None:
    if epoch is not None and epoch.utcoffset() is None:
        raise TrackingError("epoch must be timezone-aware (e.g. datetime(..., tzinfo=UTC))")


def _when(epoch: datetime, t_s: float) -> datetime:
    # Milliseconds: what every format here writes, so GPX, KML and GeoPackage agree.
    return (epoch + timedelta(milliseconds=round(float(t_s) * 1000.0))).astimezone(UTC)


def iso_utc(epoch: datetime, t_s: float) -> str:
    """ISO 8601 UTC time of ``epoch + t_s`` with millisecond precision, ``Z`` suffix."""
    _check_epoch(epoch)
    when = _when(epoch, t_s)
    return when.strftime("%Y-%m-%dT%H:%M:%S.") + f"{when.microsecond // 1000:03d}Z"


def split_at_gaps(track: Track) -> list[list[int]]:
    """Point indices of the track's runs between gaps (each run non-empty)."""
    runs: list[list[int]] = []
    t = track.t_s
    for i in range(len(t)):
        if i == 0 or any(a <= t[i - 1] and t[i] <= b for a, b in track.gaps):
            runs.append([])
        runs[-1].append(i)
    return runs


@dataclass(frozen=True)
class HeightModel:
    """How exports get sea-level (orthometric) heights from ellipsoidal ones.

    Parameters
    ----------
    geoid : str or None
        Name of the geoid model (``"EGM96"``, ``"site constant N = -33.4 m"``); None when
        the site has none, and the absolute heights are then the ellipsoidal ones.
    to_orthometric : callable or None
        ``(lat_deg, lon_deg, h_m) -> H_m`` on arrays of shape (n,); required with ``geoid``.
    datum : str or None
        The name of the orthometric heights' datum for column values (``"EGM96 geoid"``);
        default ``"geoid: <geoid>"``.
    """

    geoid: str | None = None
    to_orthometric: OrthometricFn | None = None
    datum: str | None = None

    def __post_init__(self) -> None:
        if (self.geoid is None) != (self.to_orthometric is None):
            raise TrackingError("a HeightModel needs both a geoid name and its function")

    @classmethod
    def from_geoid(cls, geoid: GeoidModel) -> HeightModel:
        """The exports' heights through a site's :class:`~demtrack.core.geo.geoid.GeoidModel`.

        An ellipsoidal model gives no geoid (absolute heights are ellipsoidal, declared);
        a constant or grid model gives ``H = h - N(lat, lon)``, evaluated at each point.
        """
        if not geoid.orthometric:
            return cls()
        return cls(geoid.description, geoid.to_orthometric, geoid.datum)

    @classmethod
    def constant_undulation(cls, n_m: float, name: str | None = None) -> HeightModel:
        """``H = h - N`` with one undulation ``N`` (m) for the whole site."""
        try:
            geoid = GeoidModel.constant(n_m)
        except GeoidError as exc:
            raise TrackingError(str(exc)) from None
        model = cls.from_geoid(geoid)
        return model if name is None else replace(model, geoid=name)

    @classmethod
    def geoid_grid(cls, path: str | os.PathLike[str], name: str | None = None) -> HeightModel:
        """``H = h - N(lat, lon)`` with ``N`` from a PROJ vertical grid (EGM96: egm96_15.gtx).

        The grid is evaluated at each point (bilinear, by PROJ's ``vgridshift``).
        """
        try:
            geoid = GeoidModel.from_grid(Path(path))
        except GeoidError as exc:
            raise TrackingError(str(exc)) from None
        model = cls.from_geoid(geoid)
        return model if name is None else replace(model, geoid=name)

    @classmethod
    def for_site(cls, geoid: GeoidModel | float | None) -> HeightModel:
        """A site's model: from its :class:`GeoidModel`, or from a constant ``N`` (m).

        A number is the old ``site.json`` ``geoid_undulation_m``: 0 (its default) reads as
        "not known", so no geoid.
        """
        if isinstance(geoid, GeoidModel):
            return cls.from_geoid(geoid)
        n = float(geoid or 0.0)
        return cls.constant_undulation(n) if n != 0.0 else cls()

    @property
    def orthometric(self) -> bool:
        """Whether absolute heights are sea-level heights (a geoid model is known)."""
        return self.to_orthometric is not None

    def absolute(self, lat_deg: np.ndarray, lon_deg: np.ndarray, h_m: np.ndarray) -> np.ndarray:
        """Heights for KML ``absolute`` and GPX ``<ele>``: orthometric, else ellipsoidal."""
        h = np.asarray(h_m, dtype=float)
        if self.to_orthometric is None:
            return h.copy()
        out = np.asarray(self.to_orthometric(lat_deg, lon_deg, h), dtype=float)
        if out.shape != h.shape or not np.all(np.isfinite(out)):
            raise TrackingError("the geoid model gave no finite height for every point")
        return out

    @property
    def datum_name(self) -> str:
        """The datum of :meth:`absolute` heights: ``"EGM96 geoid"``, ``"WGS84 ellipsoid"``."""
        if self.to_orthometric is None:
            return "WGS84 ellipsoid (no geoid model)"
        return self.datum or f"geoid: {self.geoid}"

    @property
    def note(self) -> str:
        """One sentence saying what the absolute heights are."""
        if self.to_orthometric is None:
            return (
                "no geoid model at this site: absolute heights (KML absolute altitude, GPX ele)"
                " are metres above the WGS84 ellipsoid, not above sea level"
            )
        return (
            f"absolute heights (KML absolute altitude, GPX ele, elevation_m) are orthometric"
            f" metres above sea level, H = h - N with N from {self.geoid}"
        )


@dataclass(frozen=True)
class TimeBase:
    """The UTC time of ``t_s = 0`` and whether ``t_s`` are clock readings.

    Parameters
    ----------
    epoch : datetime
        Timezone-aware time of ``t_s = 0``.
    wall_clock : bool
        True when ``epoch + t_s`` is the real time (``t_s`` UNIX seconds, or the session's
        real start given); False when the epoch is only declared.
    """

    epoch: datetime = UNIX_EPOCH
    wall_clock: bool = False

    def __post_init__(self) -> None:
        _check_epoch(self.epoch)

    @classmethod
    def for_times(cls, t_s: Sequence[float], epoch: datetime | None = None) -> TimeBase:
        """The time base of UNIX seconds ``t_s`` (s, shape (n,)), or of a declared epoch.

        With ``epoch`` the times are ``epoch + t_s``, declared (not clock readings).
        Without one they are UNIX seconds: wall-clock times, unless every one is before
        2000-01-01T00:00:00Z (946684800 s), which is session seconds read from 1970, and
        the files then say so instead of claiming clock times.
        """
        if epoch is not None:
            return cls(epoch, wall_clock=False)
        relative = len(t_s) > 0 and max(t_s) < _RELATIVE_BEFORE_S
        return cls(UNIX_EPOCH, wall_clock=not relative)

    def iso(self, t_s: float) -> str:
        """ISO 8601 UTC time of ``t_s`` (milliseconds, ``Z``)."""
        return iso_utc(self.epoch, t_s)

    def datetime(self, t_s: float) -> datetime:
        """The UTC :class:`datetime` of ``t_s`` (milliseconds)."""
        return _when(self.epoch, t_s)

    @property
    def epoch_iso(self) -> str:
        """The epoch as ISO 8601 UTC."""
        return iso_utc(self.epoch, 0.0)

    @property
    def note(self) -> str:
        """One sentence saying what the times are."""
        if self.wall_clock:
            return f"times are UTC (t_s seconds after {self.epoch_iso})"
        return (
            f"times are t_s session seconds after the declared epoch {self.epoch_iso},"
            " not clock readings: the store has no wall-clock time"
        )


@dataclass(frozen=True)
class ExportTrack:
    """One track ready to write: arrays of shape (n,) and its runs between gaps."""

    track: Track
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    abs_h_m: np.ndarray
    times_utc: tuple[str, ...]
    runs: tuple[tuple[int, ...], ...]

    @property
    def t_s(self) -> list[float]:
        """Point times (s, the store's clock)."""
        return [float(p.t_s) for p in self.track.points]


def prepare_tracks(
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    heights: HeightModel,
    times: TimeBase,
) -> list[ExportTrack]:
    """Geodetic positions, absolute heights, times and runs of every non-empty track."""
    out: list[ExportTrack] = []
    for track in tracks:
        if not track.points:
            continue
        geo = np.array(
            [[float(v) for v in to_geodetic(*(float(c) for c in p))] for p in track.p_enu]
        ).reshape(-1, 3)
        lat, lon, h = geo[:, 0], geo[:, 1], geo[:, 2]
        out.append(
            ExportTrack(
                track,
                lat,
                lon,
                h,
                heights.absolute(lat, lon, h),
                tuple(times.iso(p.t_s) for p in track.points),
                tuple(tuple(r) for r in split_at_gaps(track)),
            )
        )
    return out
