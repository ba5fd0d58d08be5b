"""The camera model a GCP fit adjusts: parameter names, the parameter vector, bounds, priors.

Parameters that can be freed (``FREE_PARAMETERS``), with their units:

``yaw, tilt, roll`` (deg)
    azimuth of the optical axis clockwise from the site frame's north, its elevation
    (negative looks down) and the bank about it (see
    :func:`~demtrack.core.camera.pinhole.rotation_from_azimuth_tilt_roll`);
``f`` (px)
    the focal length with ``fx`` and ``fy`` tied (``fy`` keeps its ratio to ``fx``);
``fx, fy`` (px)
    the two focal lengths apart (``f`` and ``fx``/``fy`` exclude each other);
``cx, cy`` (px)
    principal point, pixel ``(0, 0)`` the centre of the top-left pixel;
``k1, k2, k3, p1, p2``
    OpenCV radial and tangential distortion (unitless);
``x, y, z`` (m)
    optical centre in the site frame (east, north, up).

The full parameter vector ``theta`` has the 15 entries of :data:`THETA` (``f`` is not one:
it moves ``fx`` and, through the tie, ``fy``). Bounds are ``(lo, hi)`` per free name;
priors ``(value, sigma)`` per name, entered in the fit as extra residuals
``(theta - value) / sigma * pixel_sigma_px`` so that a prior weighs like a GCP axis with
pixel noise ``pixel_sigma_px``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError, CameraError
from .lens import distort_normalized
from .pinhole import Camera, Intrinsics, rotation_from_azimuth_tilt_roll

__all__ = [
    "DEFAULT_FREE",
    "FREE_PARAMETERS",
    "THETA",
    "FitModel",
    "camera_of",
    "params_of",
    "parse_bounds",
    "parse_free",
    "parse_priors",
    "project",
]

#: Parameters that can be freed, in canonical order.
FREE_PARAMETERS = (
    "yaw", "tilt", "roll", "f", "fx", "fy", "cx", "cy",
    "k1", "k2", "k3", "p1", "p2", "x", "y", "z",
)  # fmt: skip
#: Parameters freed by default: the orientation.
DEFAULT_FREE = ("yaw", "tilt", "roll")
#: Entries of the full parameter vector.
THETA = ("yaw", "tilt", "roll", "fx", "fy", "cx", "cy", "k1", "k2", "k3", "p1", "p2", "x", "y", "z")
_INDEX = {name: THETA.index(name) for name in THETA} | {"f": THETA.index("fx")}


def parse_free(text: str) -> tuple[str, ...]:
    """``"yaw,tilt,f"`` -> ``("yaw", "tilt", "f")`` in canonical order.

    Raises
    ------
    CalibrationError
        On an unknown or repeated name, an empty list, or ``f`` with ``fx``/``fy``.
    """
    names = [t.strip().lower() for t in text.split(",") if t.strip()]
    unknown = [n for n in names if n not in FREE_PARAMETERS]
    if unknown:
        raise CalibrationError(
            f"unknown parameter(s) {', '.join(unknown)}; choose from {','.join(FREE_PARAMETERS)}"
        )
    if not names:
        raise CalibrationError("no parameter to fit: --free must name at least one")
    if len(set(names)) != len(names):
        raise CalibrationError(f"--free names a parameter twice: {text}")
    if "f" in names and ({"fx", "fy"} & set(names)):
        raise CalibrationError(
            "--free: 'f' ties fx and fy together; free either f or fx,fy, not both"
        )
    return tuple(n for n in FREE_PARAMETERS if n in names)


def _pairs(items: Sequence[str], what: str, count: int) -> dict[str, tuple[float, ...]]:
    out: dict[str, tuple[float, ...]] = {}
    for item in items:
        name, sep, rest = item.partition("=")
        name = name.strip().lower()
        try:
            values = tuple(float(v) for v in rest.split(","))
        except ValueError:
            values = ()
        if not sep or len(values) != count or not all(math.isfinite(v) for v in values):
            form = "NAME=LO,HI" if what == "bound" else "NAME=VALUE,SIGMA"
            raise CalibrationError(f"--{what} {item!r} is malformed: write {form}")
        if name not in FREE_PARAMETERS:
            raise CalibrationError(
                f"--{what} {item!r}: unknown parameter {name!r}; choose from "
                f"{','.join(FREE_PARAMETERS)}"
            )
        if name in out:
            raise CalibrationError(f"--{what} names {name!r} twice")
        out[name] = values
    return out


def parse_bounds(items: Sequence[str]) -> dict[str, tuple[float, float]]:
    """``["fx=900,1100", ...]`` -> ``{"fx": (900.0, 1100.0)}``.

    Raises
    ------
    CalibrationError
        On a malformed item, an unknown name, or ``lo >= hi``.
    """
    out: dict[str, tuple[float, float]] = {}
    for name, (lo, hi) in _pairs(items, "bound", 2).items():
        if not lo < hi:
            raise CalibrationError(
                f"--bound {name}={lo:g},{hi:g}: the lower bound must be below the upper"
            )
        out[name] = (lo, hi)
    return out


def parse_priors(items: Sequence[str]) -> dict[str, tuple[float, float]]:
    """``["fx=1000,20", ...]`` -> ``{"fx": (1000.0, 20.0)}`` (value, 1-sigma).

    Raises
    ------
    CalibrationError
        On a malformed item, an unknown name, or a sigma that is not positive.
    """
    out: dict[str, tuple[float, float]] = {}
    for name, (value, sigma) in _pairs(items, "prior", 2).items():
        if not sigma > 0:
            raise CalibrationError(f"--prior {name}: its sigma must be positive, got {sigma:g}")
        out[name] = (value, sigma)
    return out


def params_of(camera: Camera) -> np.ndarray:
    """The full parameter vector (:data:`THETA` order) of a camera, shape (15,)."""
    az, tilt, roll = camera.azimuth_tilt_roll_deg()
    i = camera.intrinsics
    return np.array(
        [az, tilt, roll, i.fx, i.fy, i.cx, i.cy, i.k1, i.k2, i.k3, i.p1, i.p2,
         *camera.position_enu]
    )  # fmt: skip


def project(
    theta: np.ndarray, p_enu: np.ndarray, fy_ratio: float | None, k4: float = 0.0
) -> np.ndarray:
    """Pixels ``(n, 2)`` of site-frame points ``(n, 3)``; NaN behind the camera.

    ``fy_ratio``: when not None, ``fy = fx * fy_ratio`` (``f`` free) instead of ``theta``'s.
    ``k4``: the lens's fixed ``r^8`` radial term (never freed; kept as the camera has it).
    """
    az, tilt, roll, fx, fy, cx, cy, k1, k2, k3, p1, p2 = theta[:12]
    if fy_ratio is not None:
        fy = fx * fy_ratio
    r = rotation_from_azimuth_tilt_roll(az, tilt, roll)
    p_cam = (p_enu - theta[12:15]) @ r
    z = p_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = np.where(z > 0, p_cam[:, 0] / z, np.nan)
        yn = np.where(z > 0, p_cam[:, 1] / z, np.nan)
    xd, yd = distort_normalized(xn, yn, k1, k2, p1, p2, k3, k4)
    return np.column_stack([fx * xd + cx, fy * yd + cy])


def camera_of(theta: np.ndarray, base: Intrinsics, fy_ratio: float | None) -> Camera:
    """The camera of a parameter vector (image size from ``base``).

    Raises
    ------
    CalibrationError
        When the fitted lens is not a usable camera (e.g. its distortion folds).
    """
    az, tilt, roll, fx, fy, cx, cy, k1, k2, k3, p1, p2 = (float(t) for t in theta[:12])
    if fy_ratio is not None:
        fy = fx * fy_ratio
    try:
        intr = Intrinsics(fx, fy, cx, cy, base.width, base.height, k1, k2, p1, p2, k3, base.k4)
    except CameraError as exc:
        raise CalibrationError(
            f"the fitted lens model is unusable ({exc}); free fewer distortion terms"
        ) from None
    tilt = min(90.0, max(-90.0, tilt))
    return Camera.from_azimuth_tilt_roll(intr, theta[12:15], az % 360.0, tilt, roll)


@dataclass(frozen=True, eq=False)
class FitModel:
    """Which entries of ``theta`` a fit moves, within which bounds, under which priors.

    Attributes
    ----------
    free : tuple of str
        Free names (canonical order).
    index : ndarray of int, shape (p,)
        Their positions in ``theta``.
    fy_ratio : float or None
        ``fy / fx`` kept when ``f`` is free; None otherwise.
    lo, hi : ndarray, shape (p,)
        Bounds of the free entries.
    prior_index : ndarray of int, shape (q,)
        Positions in ``theta`` of the entries with a prior.
    prior_value, prior_sigma : ndarray, shape (q,)
    """

    free: tuple[str, ...]
    index: np.ndarray
    fy_ratio: float | None
    lo: np.ndarray
    hi: np.ndarray
    prior_index: np.ndarray
    prior_value: np.ndarray
    prior_sigma: np.ndarray
    k4: float = 0.0

    @classmethod
    def build(
        cls,
        free: Sequence[str],
        theta0: np.ndarray,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        priors: Mapping[str, tuple[float, float]] | None = None,
    ) -> FitModel:
        """Check and assemble a model around the start ``theta0``.

        Raises
        ------
        CalibrationError
            When a bound names a parameter that is not free or excludes its start value,
            or a prior names a parameter that is not free.
        """
        free = parse_free(",".join(free))
        index = np.array([_INDEX[n] for n in free], dtype=np.int64)
        lo = np.full(len(free), -np.inf)
        hi = np.full(len(free), np.inf)
        for j, name in enumerate(free):
            if name == "tilt":
                lo[j], hi[j] = -90.0, 90.0
            elif name in ("f", "fx", "fy"):
                lo[j] = 1e-6 * theta0[index[j]]
        for name, (b_lo, b_hi) in (bounds or {}).items():
            if name not in free:
                raise CalibrationError(f"--bound {name}: {name!r} is not a free parameter")
            j = free.index(name)
            start = float(theta0[index[j]])
            if name == "yaw":
                start = _yaw_near(start, 0.5 * (b_lo + b_hi))
                theta0[index[j]] = start
            if not b_lo <= start <= b_hi:
                raise CalibrationError(
                    f"--bound {name}={b_lo:g},{b_hi:g} excludes its starting value {start:g}"
                )
            lo[j], hi[j] = max(lo[j], b_lo), min(hi[j], b_hi)
        p_idx, p_val, p_sig = [], [], []
        for name, (value, sigma) in (priors or {}).items():
            if name not in free:
                raise CalibrationError(f"--prior {name}: {name!r} is not a free parameter")
            p_idx.append(_INDEX[name])
            p_val.append(value)
            p_sig.append(sigma)
        ratio = float(theta0[4] / theta0[3]) if "f" in free else None
        return cls(
            free, index, ratio, lo, hi,
            np.array(p_idx, dtype=np.int64), np.array(p_val, float), np.array(p_sig, float),
        )  # fmt: skip

    @property
    def n_priors(self) -> int:
        """Number of prior residuals."""
        return int(self.prior_index.size)

    def prior_residuals(self, theta: np.ndarray, pixel_sigma_px: float) -> np.ndarray:
        """``(theta - value) / sigma * pixel_sigma_px`` per prior, shape (q,)."""
        return (theta[self.prior_index] - self.prior_value) / self.prior_sigma * pixel_sigma_px


def _yaw_near(yaw: float, centre: float) -> float:
    """``yaw`` moved by whole turns to within 180 deg of ``centre``."""
    return centre + ((yaw - centre + 180.0) % 360.0) - 180.0
