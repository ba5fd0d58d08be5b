"""Pinhole cameras with OpenCV lens distortion, posed in the site's local ENU frame.

Conventions (``docs/conventions.md``):

* Camera frame is OpenCV's: x right, y down, z forward along the optical axis.
  ``R_world_cam`` rotates camera-frame vectors into the local ENU frame, so
  ``p_enu = R_world_cam @ p_cam + position_enu``.
* Pixels ``(u, v)`` are (column, row) and pixel ``(0, 0)`` is the **centre** of the
  top-left pixel: the image spans ``u in [-0.5, width - 0.5]``,
  ``v in [-0.5, height - 0.5]``. OpenCV calibrations use the same convention, so their
  ``cx, cy`` are taken as they are.
* Lens model: OpenCV's radial (``k1, k2, k3``) and tangential (``p1, p2``) distortion of
  the ideal normalised coordinates, plus an optional ``r^8`` radial term ``k4`` (the
  polynomial one of Metashape and weitsicht, not OpenCV's rational ``k4``), inverted by
  damped Newton iteration: stated in full in ``core.camera.lens``. :class:`Intrinsics`
  refuses coefficients whose radial model folds back inside the image.

The lens model's array functions live in ``core.camera.lens`` (its numba kernel in
``core.camera._lens_kernels``); the classes here validate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import CameraError
from .lens import (
    distort_normalized,
    distortion_jacobian,
    radial_fold_radius,
    undistort_normalized,
    undistort_normalized_nb,
)

__all__ = [
    "CAMERA_FORMAT",
    "CAMERA_FORMAT_VERSION",
    "Camera",
    "Intrinsics",
    "rotation_from_azimuth_tilt_roll",
]

#: ``format`` tag and version of :meth:`Camera.to_dict` documents.
CAMERA_FORMAT = "demtrack.camera"
CAMERA_FORMAT_VERSION = 1

_INTRINSIC_KEYS = (
    "fx", "fy", "cx", "cy", "width", "height", "k1", "k2", "p1", "p2", "k3", "k4",
)  # fmt: skip


def rotation_from_azimuth_tilt_roll(
    az_deg: float, tilt_deg: float, roll_deg: float = 0.0
) -> np.ndarray:
    """``R_world_cam`` for a camera aimed by azimuth, tilt and roll.

    Parameters
    ----------
    az_deg : float
        Azimuth of the optical axis, clockwise from true north (local +Y), degrees.
    tilt_deg : float
        Elevation of the optical axis above the horizontal, degrees (negative = down).
    roll_deg : float
        Rotation about the optical axis, degrees; positive lowers the image's right side
        (right-wing-down, as an aircraft's bank), so the horizon appears rotated
        counter-clockwise in the image.

    Returns
    -------
    ndarray, shape (3, 3)
        Columns are the camera x (right), y (down), z (forward) axes in ENU.
    """
    az, tilt, roll = np.radians([az_deg, tilt_deg, roll_deg])
    forward = np.array([np.sin(az) * np.cos(tilt), np.cos(az) * np.cos(tilt), np.sin(tilt)])
    # At zero roll the image x axis is horizontal: it is the azimuth's right-hand side.
    right0 = np.array([np.cos(az), -np.sin(az), 0.0])
    down0 = np.cross(forward, right0)
    right = np.cos(roll) * right0 + np.sin(roll) * down0
    down = np.cos(roll) * down0 - np.sin(roll) * right0
    return np.column_stack([right, down, forward])


# ---------------------------------------------------------------------------------------
# Intrinsics
# ---------------------------------------------------------------------------------------


def _finite(name: str, value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise CameraError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise CameraError(f"{name} must be finite, got {out}")
    return out


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics with OpenCV distortion.

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels (> 0).
    cx, cy : float
        Principal point in pixels, with pixel (0, 0) the centre of the top-left pixel.
    width, height : int
        Image size in pixels (>= 1).
    k1, k2, p1, p2, k3 : float
        OpenCV radial (k) and tangential (p) distortion coefficients.
    k4 : float
        Radial coefficient of ``r^8`` (``g = 1 + k1 r^2 + k2 r^4 + k3 r^6 + k4 r^8``): the
        polynomial term of Metashape's and weitsicht's Brown model, **not** OpenCV's
        rational ``k4``. Default 0 (OpenCV's five-coefficient model).

    Raises
    ------
    CameraError
        On non-finite or non-positive values, or when the distortion model is not
        invertible over the image (it folds back inside the corner radius).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    #: Undistorted normalised radius where the radial model folds (``inf`` if never).
    fold_radius: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        if self.fx <= 0 or self.fy <= 0:
            raise CameraError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        for name in ("width", "height"):
            value = _finite(name, getattr(self, name))
            if value != int(value) or value < 1:
                raise CameraError(
                    f"{name} must be a positive whole number of pixels, got {getattr(self, name)!r}"
                )
            object.__setattr__(self, name, int(value))
        r_fold = radial_fold_radius(self.k1, self.k2, self.k3, self.k4)
        object.__setattr__(self, "fold_radius", r_fold)
        if self.has_distortion:
            self._check_invertible()

    @property
    def coeffs(self) -> tuple[float, float, float, float, float]:
        """OpenCV's five distortion coefficients ``(k1, k2, p1, p2, k3)``.

        What ``cv2`` takes as ``distCoeffs``. It leaves out ``k4`` (OpenCV has no
        polynomial ``r^8`` term); the lens functions take :attr:`lens_coeffs`.
        """
        return (self.k1, self.k2, self.p1, self.p2, self.k3)

    @property
    def lens_coeffs(self) -> tuple[float, float, float, float, float, float]:
        """All six coefficients ``(k1, k2, p1, p2, k3, k4)``, as ``core.camera.lens`` takes them."""
        return (self.k1, self.k2, self.p1, self.p2, self.k3, self.k4)

    @property
    def has_distortion(self) -> bool:
        """True if any distortion coefficient is non-zero."""
        return any(c != 0.0 for c in self.lens_coeffs)

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the calibration matrix is K everywhere
        """The 3x3 calibration matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def corners_px(self) -> tuple[np.ndarray, np.ndarray]:
        """Outer corners of the image, ``(u, v)`` each shape (4,): TL, TR, BR, BL."""
        u0, u1, v0, v1 = -0.5, self.width - 0.5, -0.5, self.height - 0.5
        return np.array([u0, u1, u1, u0]), np.array([v0, v0, v1, v1])

    def _check_invertible(self) -> None:
        u, v = self.corners_px()
        rd_corner = float(np.max(np.hypot((u - self.cx) / self.fx, (v - self.cy) / self.fy)))
        r_fold = self.fold_radius
        if math.isfinite(r_fold):
            s = r_fold * r_fold
            rho_fold = r_fold * (1.0 + s * (self.k1 + s * (self.k2 + s * (self.k3 + s * self.k4))))
            if not rho_fold > rd_corner:
                raise CameraError(
                    "distortion is not invertible within the image: the radial model "
                    f"(k1={self.k1}, k2={self.k2}, k3={self.k3}, k4={self.k4}) folds back at "
                    f"distorted radius {rho_fold:.6g} (normalised), inside the image corner radius "
                    f"{rd_corner:.6g}"
                )
        # Radial monotonicity settles the radial-only model exactly; tangential terms can
        # still fold the 2-D map, so check a grid of pixels over the whole image too.
        gu = np.linspace(-0.5, self.width - 0.5, 25)
        gv = np.linspace(-0.5, self.height - 0.5, 25)
        uu, vv = np.meshgrid(gu, gv)
        # The numpy twin: no compilation just to build an Intrinsics.
        xn, yn = undistort_normalized(
            (uu - self.cx) / self.fx,
            (vv - self.cy) / self.fy,
            *self.lens_coeffs,
            r_max=self.fold_radius,
        )
        if not (np.isfinite(xn).all() and np.isfinite(yn).all()):
            raise CameraError(
                "distortion is not invertible within the image: some pixels "
                f"have no undistorted preimage (coefficients {self.lens_coeffs})"
            )
        a, b, c, d = distortion_jacobian(xn, yn, *self.lens_coeffs)
        if not (a * d - b * c > 0.0).all():
            raise CameraError(
                "distortion is not invertible within the image: its Jacobian "
                f"is singular or reflecting (coefficients {self.lens_coeffs})"
            )

    def distort(self, xn: ArrayLike, yn: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalised coordinates to (distorted) pixels.

        Parameters
        ----------
        xn, yn : array_like
            Ideal normalised camera coordinates ``x/z, y/z`` (broadcast together).

        Returns
        -------
        u, v : ndarray, float64
            Pixel coordinates; NaN beyond the radial fold (where the model is invalid).
        """
        xn = np.asarray(xn, dtype=np.float64)
        yn = np.asarray(yn, dtype=np.float64)
        xd, yd = distort_normalized(xn, yn, *self.lens_coeffs)
        u = self.fx * xd + self.cx
        v = self.fy * yd + self.cy
        if math.isfinite(self.fold_radius):
            beyond = ~(xn * xn + yn * yn < self.fold_radius**2)
            u = np.where(beyond, np.nan, u)
            v = np.where(beyond, np.nan, v)
        return u, v

    def undistort(self, u: ArrayLike, v: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Pixels to ideal normalised coordinates (exact inverse of :meth:`distort`).

        Parameters
        ----------
        u, v : array_like
            Pixel coordinates (broadcast together); pixels outside the image are allowed.

        Returns
        -------
        xn, yn : ndarray, float64
            Ideal normalised camera coordinates; NaN where no preimage exists.
        """
        xd = (np.asarray(u, dtype=np.float64) - self.cx) / self.fx
        yd = (np.asarray(v, dtype=np.float64) - self.cy) / self.fy
        return undistort_normalized_nb(xd, yd, *self.lens_coeffs, r_max=self.fold_radius)

    def in_image(self, u: ArrayLike, v: ArrayLike) -> np.ndarray:
        """Flag pixels on the image, edges included (NaN counts as outside)."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        return (u >= -0.5) & (u <= self.width - 0.5) & (v >= -0.5) & (v <= self.height - 0.5)

    def to_dict(self) -> dict[str, float | int]:
        """Plain JSON-ready mapping of the parameters (keys as the constructor's).

        ``k4`` is written only when non-zero, so five-coefficient cameras keep the
        eleven keys that earlier demtrack versions wrote and read.
        """
        out = {k: getattr(self, k) for k in _INTRINSIC_KEYS}
        if out["k4"] == 0.0:
            del out["k4"]
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Intrinsics:
        """Inverse of :meth:`to_dict`; distortion keys may be omitted (zero)."""
        if not isinstance(data, dict):
            raise CameraError(f"intrinsics must be a mapping, got {type(data).__name__}")
        unknown = sorted(set(data) - set(_INTRINSIC_KEYS))
        if unknown:
            raise CameraError(f"unknown intrinsics keys {unknown}; expected {_INTRINSIC_KEYS}")
        missing = [k for k in _INTRINSIC_KEYS[:6] if k not in data]
        if missing:
            raise CameraError(f"intrinsics missing keys {missing}")
        return cls(**data)


# ---------------------------------------------------------------------------------------
# Camera
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Camera:
    """A posed camera in the local ENU frame.

    Parameters
    ----------
    intrinsics : Intrinsics
        Lens and sensor model.
    position_enu : array_like, shape (3,)
        Optical centre in the local frame (m).
    R_world_cam : array_like, shape (3, 3)
        Rotation taking camera-frame (OpenCV) vectors to ENU; must be a proper rotation
        (orthonormal to 1e-9, determinant +1).
    """

    intrinsics: Intrinsics
    position_enu: np.ndarray
    R_world_cam: np.ndarray  # noqa: N815 - frame names follow the project's convention

    def __post_init__(self) -> None:
        if not isinstance(self.intrinsics, Intrinsics):
            raise CameraError("intrinsics must be an Intrinsics instance")
        pos = np.array(self.position_enu, dtype=np.float64)
        rot = np.array(self.R_world_cam, dtype=np.float64)
        if pos.shape != (3,) or not np.isfinite(pos).all():
            raise CameraError(f"position_enu must be 3 finite numbers, got {self.position_enu!r}")
        if rot.shape != (3, 3) or not np.isfinite(rot).all():
            raise CameraError("R_world_cam must be a finite 3x3 matrix")
        if np.abs(rot.T @ rot - np.eye(3)).max() > 1e-9 or np.linalg.det(rot) <= 0.0:
            raise CameraError("R_world_cam must be a proper rotation (orthonormal, det +1)")
        pos.setflags(write=False)
        rot.setflags(write=False)
        object.__setattr__(self, "position_enu", pos)
        object.__setattr__(self, "R_world_cam", rot)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return (
            self.intrinsics == other.intrinsics
            and np.array_equal(self.position_enu, other.position_enu)
            and np.array_equal(self.R_world_cam, other.R_world_cam)
        )

    __hash__ = None  # type: ignore[assignment]  # holds arrays

    @classmethod
    def from_azimuth_tilt_roll(
        cls,
        intrinsics: Intrinsics,
        position_enu: ArrayLike,
        az_deg: float,
        tilt_deg: float,
        roll_deg: float = 0.0,
    ) -> Camera:
        """Build a camera aimed by angles (see :func:`rotation_from_azimuth_tilt_roll`).

        Parameters
        ----------
        intrinsics : Intrinsics
        position_enu : array_like, shape (3,)
            Optical centre (m, local frame).
        az_deg : float
            Azimuth of the optical axis, clockwise from true north (local +Y).
        tilt_deg : float
            Elevation of the optical axis, in [-90, 90]; negative looks down.
        roll_deg : float
            Bank about the optical axis; positive lowers the image's right side.
        """
        az = _finite("az_deg", az_deg)
        tilt = _finite("tilt_deg", tilt_deg)
        roll = _finite("roll_deg", roll_deg)
        if not -90.0 <= tilt <= 90.0:
            raise CameraError(f"tilt_deg must be within [-90, 90], got {tilt}")
        return cls(
            intrinsics,
            np.asarray(position_enu, dtype=np.float64),
            rotation_from_azimuth_tilt_roll(az, tilt, roll),
        )

    def azimuth_tilt_roll_deg(self) -> tuple[float, float, float]:
        """Angles of the pose: ``(az_deg in [0, 360), tilt_deg, roll_deg in (-180, 180])``.

        Looking straight up or down, azimuth and roll are not separable; roll is then
        reported as 0 and the azimuth is the one that image x (right) implies.
        """
        right, forward = self.R_world_cam[:, 0], self.R_world_cam[:, 2]
        tilt = math.degrees(math.asin(max(-1.0, min(1.0, forward[2]))))
        if math.hypot(forward[0], forward[1]) < 1e-12:
            az = math.degrees(math.atan2(-right[1], right[0]))
            roll = 0.0
        else:
            az = math.degrees(math.atan2(forward[0], forward[1]))
            r0 = rotation_from_azimuth_tilt_roll(az, tilt, 0.0)
            roll = math.degrees(math.atan2(float(right @ r0[:, 1]), float(right @ r0[:, 0])))
        az %= 360.0
        if roll <= -180.0:
            roll += 360.0
        return az, tilt, roll

    def in_image(self, u: ArrayLike, v: ArrayLike) -> np.ndarray:
        """Flag pixels on the image (see :meth:`Intrinsics.in_image`)."""
        return self.intrinsics.in_image(u, v)

    def pixel_to_ray(
        self, u: ArrayLike, v: ArrayLike, check: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """Back-project pixels to rays in the local frame.

        Parameters
        ----------
        u, v : array_like
            Pixel coordinates (broadcast together, flattened to ``n`` rays).
        check : bool
            If True, raise :class:`CameraError` when any pixel is non-finite or off the
            image. If False (the array kernel), off-image pixels are back-projected too
            and NaN comes back where no ray exists.

        Returns
        -------
        origins : ndarray, shape (n, 3)
            The optical centre, repeated (m, ENU).
        directions : ndarray, shape (n, 3)
            Unit direction vectors (ENU).
        """
        u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        u, v = u.ravel(), v.ravel()
        if check:
            inside = self.in_image(u, v)
            if not inside.all():
                i = int(np.flatnonzero(~inside)[0])
                iw, ih = self.intrinsics.width, self.intrinsics.height
                raise CameraError(
                    f"pixel ({u[i]}, {v[i]}) is outside the {iw}x{ih} image "
                    f"(u in [-0.5, {iw - 0.5}], v in [-0.5, {ih - 0.5}]); "
                    f"{int((~inside).sum())} of {u.size} pixels are off the image"
                )
        xn, yn = self.intrinsics.undistort(u, v)
        d_cam = np.stack([xn, yn, np.ones_like(xn)], axis=1)
        d_cam /= np.linalg.norm(d_cam, axis=1, keepdims=True)
        directions = d_cam @ self.R_world_cam.T
        origins = np.broadcast_to(self.position_enu, directions.shape).copy()
        return origins, directions

    def project(self, points_enu: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project points of the local frame to pixels (exact inverse of pixel_to_ray).

        Parameters
        ----------
        points_enu : array_like, shape (n, 3) or (3,)
            Points in the local frame (m).

        Returns
        -------
        u, v : ndarray, shape (n,)
            Pixel coordinates, possibly off the image; NaN for points not in front of the
            camera and for points beyond the lens model's radial fold, whose pixel would
            be meaningless.
        in_front : ndarray of bool, shape (n,)
            True where the point has positive depth along the optical axis.
        """
        pts = np.asarray(points_enu, dtype=np.float64)
        if pts.ndim == 1:
            pts = pts[None, :]
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise CameraError(f"points_enu must have shape (n, 3), got {np.shape(points_enu)}")
        p_cam = (pts - self.position_enu) @ self.R_world_cam
        z = p_cam[:, 2]
        in_front = z > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = np.where(in_front, p_cam[:, 0] / z, np.nan)
            yn = np.where(in_front, p_cam[:, 1] / z, np.nan)
        u, v = self.intrinsics.distort(xn, yn)
        return u, v, in_front

    def in_view(self, points_enu: ArrayLike) -> np.ndarray:
        """True where a point projects into the image (in front, on the sensor), shape (n,)."""
        u, v, in_front = self.project(points_enu)
        ok = in_front & np.isfinite(u) & np.isfinite(v)
        ok[ok] = self.in_image(u[ok], v[ok])
        return ok

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready document (format ``demtrack.camera``, version 1).

        Shape::

            {"format": "demtrack.camera", "version": 1,
             "intrinsics": {"fx", "fy", "cx", "cy", "width", "height",
                            "k1", "k2", "p1", "p2", "k3", "k4"?},
             "position_enu": [e_m, n_m, u_m],
             "R_world_cam": [[...], [...], [...]]}        # row-major

        :meth:`from_dict` also accepts ``"orientation": {"az_deg", "tilt_deg",
        "roll_deg"?}`` in place of ``R_world_cam`` for hand-written site files.
        """
        return {
            "format": CAMERA_FORMAT,
            "version": CAMERA_FORMAT_VERSION,
            "intrinsics": self.intrinsics.to_dict(),
            "position_enu": [float(x) for x in self.position_enu],
            "R_world_cam": [[float(x) for x in row] for row in self.R_world_cam],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Camera:
        """Inverse of :meth:`to_dict`; raises :class:`CameraError` on a malformed document."""
        if not isinstance(data, dict):
            raise CameraError(f"camera document must be a mapping, got {type(data).__name__}")
        if data.get("format") != CAMERA_FORMAT:
            raise CameraError(
                f"not a camera document: format is {data.get('format')!r}, "
                f"expected {CAMERA_FORMAT!r}"
            )
        if data.get("version") != CAMERA_FORMAT_VERSION:
            raise CameraError(
                f"unsupported camera document version {data.get('version')!r}; "
                f"this demtrack reads version {CAMERA_FORMAT_VERSION}"
            )
        allowed = {"format", "version", "intrinsics", "position_enu", "R_world_cam", "orientation"}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise CameraError(f"unknown camera document keys {unknown}")
        for key in ("intrinsics", "position_enu"):
            if key not in data:
                raise CameraError(f"camera document has no {key!r}")
        intr = Intrinsics.from_dict(data["intrinsics"])
        has_r, has_o = "R_world_cam" in data, "orientation" in data
        if has_r == has_o:
            raise CameraError(
                "camera document needs exactly one of 'R_world_cam' and 'orientation'"
            )
        if has_r:
            return cls(intr, data["position_enu"], data["R_world_cam"])
        o = data["orientation"]
        if (
            not isinstance(o, dict)
            or not {"az_deg", "tilt_deg"} <= set(o)
            or not set(o) <= {"az_deg", "tilt_deg", "roll_deg"}
        ):
            raise CameraError("orientation must be {'az_deg', 'tilt_deg', 'roll_deg'?}")
        return cls.from_azimuth_tilt_roll(
            intr, data["position_enu"], o["az_deg"], o["tilt_deg"], o.get("roll_deg", 0.0)
        )
