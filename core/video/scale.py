"""How large a person looks at each pixel: the camera and the DEM give pixels per metre.

A blob's foot pixel geolocates to a ground point at a known range; a person standing
there (the classifier's human prototype, 0.6 m x 1.7 m) covers a known number of
pixels. :func:`person_area_map` evaluates that on a grid of foot pixels (one ray per
``step_px`` x ``step_px`` block, bilinear in between) so that the detector's minimum
blob area can follow the range (:meth:`~.detector.VsamDetector.set_min_area_map`): a
walker 250 m from a 819 px lens is 2 px wide and 6-8 px tall, a dozen pixels, which a
fixed 16 px floor drops, while noise of that size next to the camera is still dropped.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from .classify import PROTOTYPES

__all__ = ["min_area_map", "person_area_map"]


def _person_size() -> tuple[float, float]:
    for cls, w, h, _ in PROTOTYPES:
        if cls == "human":
            return w, h
    raise AssertionError("no human prototype")  # pragma: no cover


def person_area_map(camera: Any, geolocator: Any, *, step_px: int = 16) -> np.ndarray:
    """The area (px) of a person whose foot pixel is each pixel of ``camera``'s image.

    Width across the line of sight times height up the vertical at the foot pixel's
    first ground hit (the classifier's human prototype). NaN where the ray meets no
    ground (the sky) or the projection fails.

    Returns
    -------
    ndarray of float32, shape (height, width)
    """
    w_img, h_img = int(camera.intrinsics.width), int(camera.intrinsics.height)
    us = np.arange(0.0, w_img + step_px, step_px).clip(max=w_img - 1.0)
    vs = np.arange(0.0, h_img + step_px, step_px).clip(max=h_img - 1.0)
    uu, vv = np.meshgrid(us, vs)
    hits = geolocator.locate_pixels([(camera, uu.ravel(), vv.ravel())])
    person_w, person_h = _person_size()
    cam = np.asarray(camera.position_enu, dtype=np.float64)
    area = np.full(uu.size, np.nan)
    offsets = np.asarray(hits.offsets)
    has = offsets[1:] > offsets[:-1]
    if has.any():
        p = np.asarray(hits.points_enu)[offsets[:-1][has]]
        los = p - cam
        across = np.stack([los[:, 1], -los[:, 0], np.zeros(len(p))], axis=1)
        across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-9)
        up = np.array([0.0, 0.0, person_h])
        pts = np.concatenate([p - 0.5 * person_w * across, p + 0.5 * person_w * across, p, p + up])
        u, v, _ = camera.project(pts)
        n = len(p)
        width = np.hypot(u[n : 2 * n] - u[:n], v[n : 2 * n] - v[:n])
        height = np.hypot(u[3 * n :] - u[2 * n : 3 * n], v[3 * n :] - v[2 * n : 3 * n])
        area[has] = width * height
    # bilinear between the grid's rays; a block with a sky corner stays NaN
    interp = RegularGridInterpolator((vs, us), area.reshape(uu.shape))
    rows, cols = np.mgrid[0:h_img, 0:w_img]
    return (
        interp(np.stack([rows.ravel(), cols.ravel()], axis=1))
        .reshape(h_img, w_img)
        .astype(np.float32)
    )


def min_area_map(
    person_area_px: np.ndarray, *, fraction: float = 0.4, floor_px: float = 4.0, ceil_px: float
) -> np.ndarray:
    """The minimum blob area per foot pixel: ``fraction`` of a person there, within bounds.

    ``ceil_px`` (the detector's fixed minimum) where the person is large and where the
    foot pixel sees no ground; never under ``floor_px``.
    """
    out = np.clip(np.float32(fraction) * person_area_px, floor_px, ceil_px)
    return np.where(np.isfinite(out), out, np.float32(ceil_px)).astype(np.float32)
