"""Pan-tilt heads on a levelled tripod, and their mount-yaw calibration from landmarks.

This is the camera model of the VSAM report (Collins et al. 1998): the head sits at a
surveyed point ``(x0, y0, z0)`` on a levelled tripod, so the mount has no roll and no
tilt, and its only unknown is the **mount yaw**, the azimuth the camera looks at when the
head's pan reads zero. A commanded ``(pan, tilt)`` then gives a camera with azimuth
``mount_yaw + pan`` (clockwise from true north) and elevation ``tilt``. The optical centre
is taken to lie on both rotation axes, as in the report.

Yaw calibration: for each landmark with surveyed ``(x_i, y_i)`` the operator pans until
it is centred in the image and records ``pan_i``. The landmark's bearing (azimuth from the
head, clockwise from north) is ``bearing_i = atan2(x_i - x0, y_i - y0)`` -- east first,
north second -- each landmark gives ``yaw_i = bearing_i - pan_i``, and the estimate is the
circular mean ``atan2(sum sin yaw_i, sum cos yaw_i)``, which, unlike an arithmetic mean,
is right for yaws that straddle +-180 degrees.

Mapping to the report's formula: it writes ``yaw_i = atan2(y_i - y0, x_i - x0) - pan_i``
with angles counter-clockwise from east (mathematical convention) and pan in that same
sense. Our azimuths are clockwise from north, ``az = 90 deg - theta_math``, so
``atan2(x_i - x0, y_i - y0) = 90 deg - atan2(y_i - y0, x_i - x0)`` and our clockwise pan
is minus a counter-clockwise one. Substituting both gives ``yaw_az = 90 deg - yaw_math``:
the same calibration, written in the project's convention.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import CalibrationError, CameraError
from .pinhole import Camera, Intrinsics

__all__ = [
    "PANTILT_FORMAT",
    "PANTILT_FORMAT_VERSION",
    "LandmarkReading",
    "PanTiltHead",
    "YawCalibration",
    "calibrate_mount_yaw",
    "wrap_deg",
]

#: ``format`` tag and version of :meth:`PanTiltHead.to_dict` documents.
PANTILT_FORMAT = "demtrack.pantilt"
PANTILT_FORMAT_VERSION = 1

#: Landmarks closer than this (horizontal metres) to the head have no usable bearing.
MIN_HORIZONTAL_DISTANCE_M = 1e-6


def wrap_deg(angle_deg: ArrayLike) -> np.ndarray:
    """Wrap angles to the half-open interval (-180, 180] degrees."""
    a = np.asarray(angle_deg, dtype=np.float64)
    w = np.mod(a + 180.0, 360.0) - 180.0  # in [-180, 180)
    return np.where(w == -180.0, 180.0, w)


@dataclass(frozen=True)
class LandmarkReading:
    """One landmark sighting: surveyed position and the pan that centred it.

    Parameters
    ----------
    name : str
        Label shown to the operator.
    e, n : float
        Surveyed east and north coordinates in the local frame (m).
    pan_deg : float
        Head pan reading (degrees, clockwise-positive) with the landmark centred.
    u : float or None
        Surveyed up coordinate (m, local frame), if known; the yaw does not use it.
    """

    name: str
    e: float
    n: float
    pan_deg: float
    u: float | None = None

    def __post_init__(self) -> None:
        for key in ("e", "n", "pan_deg") + (("u",) if self.u is not None else ()):
            value = getattr(self, key)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise CalibrationError(
                    f"landmark {self.name!r}: {key} must be a number, got {getattr(self, key)!r}"
                ) from None
            if not math.isfinite(value):
                raise CalibrationError(f"landmark {self.name!r}: {key} must be finite")
            object.__setattr__(self, key, value)
        object.__setattr__(self, "name", str(self.name))

    def to_dict(self) -> dict[str, Any]:
        """``{name, e, n, u?, pan_deg}`` (``u`` only when known)."""
        out: dict[str, Any] = {"name": self.name, "e": self.e, "n": self.n}
        if self.u is not None:
            out["u"] = self.u
        out["pan_deg"] = self.pan_deg
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LandmarkReading:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(data, dict):
            raise CalibrationError(f"landmark reading must be a mapping, got {data!r}")
        unknown = sorted(set(data) - {"name", "e", "n", "u", "pan_deg"})
        missing = sorted({"name", "e", "n", "pan_deg"} - set(data))
        if unknown or missing:
            raise CalibrationError(
                f"landmark reading {data.get('name')!r}: missing keys "
                f"{missing}, unknown keys {unknown}"
            )
        return cls(data["name"], data["e"], data["n"], data["pan_deg"], data.get("u"))


@dataclass(frozen=True, eq=False)
class YawCalibration:
    """Result of :func:`calibrate_mount_yaw`.

    Attributes
    ----------
    yaw_deg : float
        Estimated mount yaw, azimuth at pan 0, in (-180, 180].
    yaws_deg : ndarray, shape (k,)
        Per-landmark yaw ``bearing_i - pan_i`` wrapped to (-180, 180].
    bearings_deg : ndarray, shape (k,)
        Azimuth of each landmark from the head, clockwise from north, in (-180, 180].
    distances_m : ndarray, shape (k,)
        Horizontal distance of each landmark from the head.
    residuals_deg : ndarray, shape (k,)
        ``wrap(yaw_i - yaw_deg)``: how far clockwise of the calibrated pointing direction
        each landmark lies when the head reads ``pan_i``.
    rms_deg : float
        Root mean square of the residuals of the landmarks used for the yaw.
    outliers : ndarray of bool, shape (k,)
        Residuals larger than the threshold in magnitude; always reported, and left out
        of the yaw when calibrating with ``reject_outliers``.
    outlier_threshold_deg : float
        The threshold used.
    warnings : tuple of str
        Plain-language notes for the operator (outliers, a single landmark, ...).
    """

    yaw_deg: float
    yaws_deg: np.ndarray
    bearings_deg: np.ndarray
    distances_m: np.ndarray
    residuals_deg: np.ndarray
    rms_deg: float
    outliers: np.ndarray
    outlier_threshold_deg: float
    warnings: tuple[str, ...] = field(default=())


def calibrate_mount_yaw(
    position_enu: ArrayLike,
    landmarks_enu: ArrayLike,
    pans_deg: ArrayLike,
    outlier_threshold_deg: float = 1.0,
    names: list[str] | None = None,
    reject_outliers: bool = True,
) -> YawCalibration:
    """Estimate a pan-tilt head's mount yaw from centred landmarks.

    Parameters
    ----------
    position_enu : array_like, shape (2,) or (3,)
        Surveyed head position ``(x0, y0[, z0])`` in the local frame (m).
    landmarks_enu : array_like, shape (k, 2) or (k, 3)
        Surveyed landmark positions (m); only east and north are used.
    pans_deg : array_like, shape (k,)
        Pan readings (degrees, clockwise-positive) with each landmark centred.
    outlier_threshold_deg : float
        Residual magnitude above which a landmark is flagged as an outlier.
    names : list of str, optional
        Landmark labels for the warnings.
    reject_outliers : bool
        Re-estimate the yaw from the landmarks within the threshold (repeated until the
        flagged set is stable, keeping at least two). False gives the paper's plain
        circular mean over every sighting.

    Returns
    -------
    YawCalibration

    Raises
    ------
    CalibrationError
        With no landmarks, mismatched or non-finite inputs, a landmark within
        ``MIN_HORIZONTAL_DISTANCE_M`` of the head horizontally, or yaws so spread that
        their circular mean is undefined.
    """
    pos = np.asarray(position_enu, dtype=np.float64)
    lm = np.asarray(landmarks_enu, dtype=np.float64)
    pans = np.asarray(pans_deg, dtype=np.float64)
    if pos.shape not in ((2,), (3,)) or not np.isfinite(pos).all():
        raise CalibrationError(f"position_enu must be 2 or 3 finite numbers, got {pos.tolist()}")
    if lm.size == 0:
        raise CalibrationError("yaw calibration needs at least one landmark, got none")
    if lm.ndim != 2 or lm.shape[1] not in (2, 3):
        raise CalibrationError(f"landmarks_enu must have shape (k, 2) or (k, 3), got {lm.shape}")
    k = lm.shape[0]
    if pans.shape != (k,):
        raise CalibrationError(f"{k} landmarks but pans_deg has shape {pans.shape}")
    if not (np.isfinite(lm).all() and np.isfinite(pans).all()):
        raise CalibrationError("landmark positions and pans must be finite")
    if not (math.isfinite(outlier_threshold_deg) and outlier_threshold_deg > 0):
        raise CalibrationError("outlier_threshold_deg must be a positive number")
    labels = list(names) if names is not None else [f"#{i}" for i in range(k)]
    if len(labels) != k:
        raise CalibrationError(f"{k} landmarks but {len(labels)} names")

    de = lm[:, 0] - pos[0]
    dn = lm[:, 1] - pos[1]
    dist = np.hypot(de, dn)
    near = np.flatnonzero(dist < MIN_HORIZONTAL_DISTANCE_M)
    if near.size:
        raise CalibrationError(
            f"landmark {labels[near[0]]} is at the head's position "
            f"(horizontal distance {dist[near[0]]:.3g} m): no bearing"
        )
    # Azimuth clockwise from north: east component first in atan2.
    bearings = np.degrees(np.arctan2(de, dn))
    yaws = wrap_deg(bearings - pans)
    s, c = np.sin(np.radians(yaws)).sum(), np.cos(np.radians(yaws)).sum()
    # Mean resultant length near zero: the yaws cancel out and have no mean direction.
    if math.hypot(s, c) / k < 1e-9:
        raise CalibrationError(
            "landmark yaws are spread evenly around the circle; their "
            "mean direction is undefined (check the pan readings)"
        )
    yaw = float(wrap_deg(math.degrees(math.atan2(s, c))))
    resid = wrap_deg(yaws - yaw)
    outliers = np.abs(resid) > outlier_threshold_deg
    # A blunder drags the circular mean by (blunder / k); re-estimate from the inliers
    # until the flagged set stops changing (at least two inliers must remain).
    for _ in range(k if reject_outliers else 0):
        inl = ~outliers
        if inl.sum() < 2 or inl.all():
            break
        rad = np.radians(yaws[inl])
        yaw = float(wrap_deg(math.degrees(math.atan2(np.sin(rad).sum(), np.cos(rad).sum()))))
        resid = wrap_deg(yaws - yaw)
        flagged = np.abs(resid) > outlier_threshold_deg
        if np.array_equal(flagged, outliers):
            break
        outliers = flagged
    used = ~outliers if reject_outliers and (~outliers).sum() >= 2 else np.ones(k, bool)
    rms = float(np.sqrt(np.mean(resid[used] ** 2)))

    notes: list[str] = []
    if k == 1:
        notes.append("a single landmark gives no check on the yaw; survey at least two")
    for i in np.flatnonzero(outliers):
        notes.append(
            f"landmark {labels[i]}: residual {resid[i]:+.3f} deg exceeds "
            f"{outlier_threshold_deg:g} deg (wrong pan reading or survey?)"
            + ("; excluded from the yaw" if not used[i] else "")
        )
    for arr in (yaws, bearings, dist, resid, outliers):
        arr.setflags(write=False)
    return YawCalibration(
        yaw_deg=yaw,
        yaws_deg=yaws,
        bearings_deg=wrap_deg(bearings),
        distances_m=dist,
        residuals_deg=resid,
        rms_deg=rms,
        outliers=outliers,
        outlier_threshold_deg=float(outlier_threshold_deg),
        warnings=tuple(notes),
    )


@dataclass(frozen=True, eq=False)
class PanTiltHead:
    """A camera on a levelled pan-tilt head.

    Parameters
    ----------
    position_enu : array_like, shape (3,)
        Surveyed optical centre ``(x0, y0, z0)`` in the local frame (m).
    mount_yaw_deg : float
        Azimuth of the optical axis at pan 0 (degrees clockwise from true north).
    intrinsics : Intrinsics
        The camera's lens model (fixed zoom).
    landmarks : tuple of LandmarkReading
        Yaw-calibration sightings kept with the head (may be empty).
    """

    position_enu: np.ndarray
    mount_yaw_deg: float
    intrinsics: Intrinsics
    landmarks: tuple[LandmarkReading, ...] = ()

    def __post_init__(self) -> None:
        pos = np.array(self.position_enu, dtype=np.float64)
        if pos.shape != (3,) or not np.isfinite(pos).all():
            raise CameraError(f"position_enu must be 3 finite numbers, got {self.position_enu!r}")
        pos.setflags(write=False)
        object.__setattr__(self, "position_enu", pos)
        try:
            yaw = float(self.mount_yaw_deg)
        except (TypeError, ValueError):
            raise CameraError(
                f"mount_yaw_deg must be a number, got {self.mount_yaw_deg!r}"
            ) from None
        if not math.isfinite(yaw):
            raise CameraError("mount_yaw_deg must be finite")
        object.__setattr__(self, "mount_yaw_deg", yaw)
        if not isinstance(self.intrinsics, Intrinsics):
            raise CameraError("intrinsics must be an Intrinsics instance")
        lms = tuple(self.landmarks)
        if not all(isinstance(r, LandmarkReading) for r in lms):
            raise CameraError("landmarks must be LandmarkReading values")
        object.__setattr__(self, "landmarks", lms)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PanTiltHead):
            return NotImplemented
        return (
            np.array_equal(self.position_enu, other.position_enu)
            and self.mount_yaw_deg == other.mount_yaw_deg
            and self.intrinsics == other.intrinsics
            and self.landmarks == other.landmarks
        )

    __hash__ = None  # type: ignore[assignment]  # holds an array

    def camera_at(self, pan_deg: float, tilt_deg: float) -> Camera:
        """Build the camera for a commanded pan and tilt (degrees).

        Its azimuth is ``mount_yaw_deg + pan_deg`` (clockwise from north), its elevation
        ``tilt_deg`` (negative looks down) and its roll 0 (levelled tripod).
        """
        return Camera.from_azimuth_tilt_roll(
            self.intrinsics,
            self.position_enu,
            self.mount_yaw_deg + float(pan_deg),
            float(tilt_deg),
            0.0,
        )

    def calibrate(
        self, outlier_threshold_deg: float = 1.0, reject_outliers: bool = True
    ) -> YawCalibration:
        """Run :func:`calibrate_mount_yaw` on the stored landmark readings."""
        if not self.landmarks:
            raise CalibrationError("this head has no landmark readings to calibrate from")
        return calibrate_mount_yaw(
            self.position_enu,
            [(r.e, r.n) for r in self.landmarks],
            [r.pan_deg for r in self.landmarks],
            outlier_threshold_deg,
            names=[r.name for r in self.landmarks],
            reject_outliers=reject_outliers,
        )

    def with_mount_yaw(self, mount_yaw_deg: float) -> PanTiltHead:
        """Return a copy with another mount yaw (e.g. ``head.calibrate().yaw_deg``)."""
        return PanTiltHead(self.position_enu, mount_yaw_deg, self.intrinsics, self.landmarks)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready document (format ``demtrack.pantilt``, version 1).

        Shape::

            {"format": "demtrack.pantilt", "version": 1,
             "position_enu": [x0_m, y0_m, z0_m],
             "mount_yaw_deg": yaw,
             "intrinsics": {... as Intrinsics.to_dict ...},
             "landmarks": [{"name", "e", "n", "u"?, "pan_deg"}, ...]}
        """
        return {
            "format": PANTILT_FORMAT,
            "version": PANTILT_FORMAT_VERSION,
            "position_enu": [float(x) for x in self.position_enu],
            "mount_yaw_deg": self.mount_yaw_deg,
            "intrinsics": self.intrinsics.to_dict(),
            "landmarks": [r.to_dict() for r in self.landmarks],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PanTiltHead:
        """Inverse of :meth:`to_dict`; ``landmarks`` may be omitted."""
        if not isinstance(data, dict):
            raise CameraError(f"pan-tilt document must be a mapping, got {type(data).__name__}")
        if data.get("format") != PANTILT_FORMAT:
            raise CameraError(
                f"not a pan-tilt document: format is {data.get('format')!r}, "
                f"expected {PANTILT_FORMAT!r}"
            )
        if data.get("version") != PANTILT_FORMAT_VERSION:
            raise CameraError(
                f"unsupported pan-tilt document version {data.get('version')!r};"
                f" this demtrack reads version {PANTILT_FORMAT_VERSION}"
            )
        required = {"position_enu", "mount_yaw_deg", "intrinsics"}
        allowed = required | {"format", "version", "landmarks"}
        missing, unknown = sorted(required - set(data)), sorted(set(data) - allowed)
        if missing or unknown:
            raise CameraError(f"pan-tilt document: missing keys {missing}, unknown keys {unknown}")
        readings = data.get("landmarks", [])
        if not isinstance(readings, list):
            raise CameraError("pan-tilt document: 'landmarks' must be a list")
        return cls(
            data["position_enu"],
            data["mount_yaw_deg"],
            Intrinsics.from_dict(data["intrinsics"]),
            tuple(LandmarkReading.from_dict(r) for r in readings),
        )
