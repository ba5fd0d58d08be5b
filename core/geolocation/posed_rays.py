"""Viewing rays of pixels seen at poses that change from pixel to pixel (a moving head).

A fixed camera's rays share one rotation and one optical centre
(:meth:`Geolocator.pixel_rays <demtrack.core.geolocation.geolocate.Geolocator.pixel_rays>`).
A PTZ head's detections are each taken at their own pose: a :class:`PosedView` holds
pixels of one lens (one zoom) with a rotation ``R_world_cam`` and an optical centre per
pixel. Its rays are made in the camera frame once for the whole view (one undistortion,
the same perturbation arithmetic as the fixed path) and each is turned into the site
frame by its own rotation, so a batch of posed detections still takes one ray cast with
the fixed ones (:meth:`~demtrack.core.geolocation.geolocate.Geolocator.locate_ray_parts`).

A zoom that changes from pixel to pixel without a calibration table (the ideal zoom of
:func:`~demtrack.core.camera.zoom_lens.intrinsics_for_hfov`) changes only the focal
lengths: a view may carry per-pixel ``fx_px``, ``fy_px`` over its lens's principal point
and distortion, and still takes one undistortion for all its pixels. Pixels the lens
model cannot invert at their zoom (beyond its radial fold, possible for zooms wider than
the calibrated one) come back as NaN rays.

A zoom that changes from pixel to pixel *with* a calibration table changes the
principal point and distortion too: a view may carry a
:class:`~demtrack.core.camera.zoom_lens.PixelLenses` (a lens per pixel, from
:meth:`ZoomTable.pixel_lenses <demtrack.core.camera.zoom_lens.ZoomTable.pixel_lenses>`)
and is undistorted in one pass with each pixel's own coefficients (a compiled kernel),
instead of one :class:`~demtrack.core.camera.pinhole.Intrinsics` per zoom. Its rays
equal those of the exact lens at each pixel's zoom to round-off (tested to 1e-9 rad on a
sweep of zooms with distortion and a moving principal point); a pixel whose own
undistortion fails, or whose distortion Jacobian is not positive there, is a NaN ray.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..camera.lens import distortion_jacobian, undistort_normalized_nb
from ..camera.pinhole import Intrinsics
from ..camera.zoom_lens import PixelLenses
from ..errors import CameraError
from ._posed_kernels import undistort_each
from .geolocate import _perturbations_from_unit, _pixels

__all__ = ["PosedView", "posed_view_rays"]


@dataclass(frozen=True, eq=False)
class PosedView:
    """Pixels of one lens, each seen at its own pose.

    Parameters
    ----------
    intrinsics : Intrinsics
        The lens (at this view's zoom).
    u, v : ndarray, shape (k,)
        Pixel columns and rows ((0, 0) the centre of the top-left pixel).
    R_world_cam : ndarray, shape (k, 3, 3)
        Per pixel, the rotation of camera-frame (OpenCV) vectors into the site frame.
    position_enu : ndarray, shape (k, 3)
        Per pixel, the optical centre (site frame, m).
    fx_px, fy_px : ndarray, shape (k,), optional
        Per-pixel focal lengths (px) in place of the lens's (a zoom without a table).
    lenses : PixelLenses, optional
        A whole lens per pixel in place of ``intrinsics``' (a zoom with a table; its
        image size is still ``intrinsics``'). Not with ``fx_px``.
    """

    intrinsics: Intrinsics
    u: np.ndarray
    v: np.ndarray
    R_world_cam: np.ndarray  # noqa: N815 - frame names follow the project's convention
    position_enu: np.ndarray
    fx_px: np.ndarray | None = None
    fy_px: np.ndarray | None = None
    lenses: PixelLenses | None = None

    def __post_init__(self) -> None:
        k = len(np.atleast_1d(self.u))
        rot = np.asarray(self.R_world_cam, dtype=np.float64)
        pos = np.asarray(self.position_enu, dtype=np.float64)
        if rot.shape != (k, 3, 3) or pos.shape != (k, 3):
            raise CameraError(
                f"a posed view of {k} pixels needs R_world_cam (k, 3, 3) and position_enu "
                f"(k, 3); got {rot.shape} and {pos.shape}"
            )
        if not (np.isfinite(rot).all() and np.isfinite(pos).all()):
            raise CameraError("a posed view's rotations and positions must be finite")
        object.__setattr__(self, "R_world_cam", rot)
        object.__setattr__(self, "position_enu", pos)
        if (self.fx_px is None) != (self.fy_px is None):
            raise CameraError("a posed view takes both fx_px and fy_px, or neither")
        for name in ("fx_px", "fy_px"):
            f = getattr(self, name)
            if f is not None:
                f = np.asarray(f, dtype=np.float64)
                if f.shape != (k,) or not (np.isfinite(f) & (f > 0)).all():
                    raise CameraError(f"{name} must be {k} positive focal lengths")
                object.__setattr__(self, name, f)
        if self.lenses is not None:
            if self.fx_px is not None:
                raise CameraError("a posed view takes per-pixel lenses or focal lengths, not both")
            if len(self.lenses.fx) != k or not np.all(self.lenses.valid):
                raise CameraError(f"a posed view of {k} pixels needs {k} valid pixel lenses")


@dataclass(frozen=True)
class _PixelLens:
    """Per-pixel focal lengths over one lens's distortion, for the perturbation arithmetic."""

    fx: Any
    fy: Any
    lens_coeffs: tuple[float, ...]


def posed_view_rays(
    view: PosedView, sigma_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rays of a posed view and their pixel perturbations, site frame.

    Parameters
    ----------
    view : PosedView
    sigma_px : float
        1-sigma pixel error, for the perturbation angles.

    Returns
    -------
    origins, directions : ndarray, shape (k, 3)
        Optical centres (m) and unit ray directions.
    perturb_axes : ndarray, shape (k, 2, 3)
        Unit directions in which each ray tips as ``u`` and as ``v`` grow.
    perturb_sigmas : ndarray, shape (k, 2)
        The angles (rad) those tips take for ``sigma_px``.

    NaN rows where the lens has no inverse at a pixel's zoom.

    Raises
    ------
    CameraError
        If a pixel lies outside the image.
    """
    u, v = _pixels(view, view.u, view.v)
    base = view.intrinsics
    intr: Any = base
    if view.lenses is not None:
        lens = view.lenses
        intr = _PixelLens(lens.fx, lens.fy, tuple(lens.coeffs.T))
        xn, yn = undistort_each(
            (u - lens.cx) / lens.fx, (v - lens.cy) / lens.fy, lens.coeffs, lens.fold_radius
        )
        # The exact lens is refused where its map folds; here, per pixel: a pixel whose
        # Jacobian is not positive at its preimage has no ray.
        a, b, c, d = distortion_jacobian(xn, yn, *intr.lens_coeffs)
        with np.errstate(invalid="ignore"):
            folded = ~(a * d - b * c > 0.0)
        xn[folded], yn[folded] = np.nan, np.nan
    elif view.fx_px is None or view.fy_px is None:
        xn, yn = base.undistort(u, v)
    else:
        intr = _PixelLens(view.fx_px, view.fy_px, base.lens_coeffs)
        k1, k2, p1, p2, k3, k4 = base.lens_coeffs
        xn, yn = undistort_normalized_nb(
            (u - base.cx) / view.fx_px,
            (v - base.cy) / view.fy_px,
            k1, k2, p1, p2, k3, k4,
            r_max=base.fold_radius,
        )  # fmt: skip
    ray = np.empty((len(xn), 3))
    ray[:, 0], ray[:, 1], ray[:, 2] = xn, yn, 1.0
    norm = np.linalg.norm(ray, axis=-1, keepdims=True)
    unit = ray / norm
    rot = view.R_world_cam
    directions = np.einsum("kij,kj->ki", rot, unit)
    # The perturbations in the camera frame (identity rotation), then each turned.
    axes_cam, sig = _perturbations_from_unit(intr, xn, yn, unit, norm, np.eye(3), sigma_px)
    axes = np.einsum("kij,kaj->kai", rot, axes_cam)
    return view.position_enu.copy(), directions, axes, sig
