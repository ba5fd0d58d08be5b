"""Blobs: connected foreground regions with their box, area, perimeter and foot pixel.

Boxes and feet are in demtrack's pixel convention (``(0, 0)`` is the centre of the
top-left pixel): a region covering columns ``c0..c1`` and rows ``r0..r1`` has the box
``(c0 - 0.5, r0 - 0.5, c1 + 0.5, r1 + 0.5)``, and its foot is the bottom-centre of that
box, ``((u_min + u_max) / 2, v_max)``, where the paper puts the object on the ground.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from .reader import Frame

__all__ = [
    "Blob",
    "Component",
    "MotionDetector",
    "blob_of",
    "blobs_from_mask",
    "components",
    "load_mask",
    "prepare_mask",
]


@dataclass(frozen=True)
class Blob:
    """One moving region of a frame.

    Attributes
    ----------
    bbox : tuple of 4 float
        ``(u_min, v_min, u_max, v_max)`` in pixels of the full frame.
    area_px : float
        Pixel count of the region (full-frame pixels).
    perimeter_px : float
        Length of its outer contour (full-frame pixels).
    foot_px : tuple of 2 float
        Bottom-centre ``(u, v)`` of the box.
    score : float or None
        Detector confidence where the detector has one (ONNX); None for motion.
    label : str or None
        Class the detector itself gave (ONNX), else None (the classifier decides).
    """

    bbox: tuple[float, float, float, float]
    area_px: float
    perimeter_px: float
    foot_px: tuple[float, float]
    score: float | None = None
    label: str | None = None

    @property
    def width_px(self) -> float:
        """Box width (px)."""
        return self.bbox[2] - self.bbox[0]

    @property
    def height_px(self) -> float:
        """Box height (px)."""
        return self.bbox[3] - self.bbox[1]

    @classmethod
    def from_box(
        cls,
        bbox: tuple[float, float, float, float],
        *,
        score: float | None = None,
        label: str | None = None,
    ) -> Blob:
        """A blob that is all box (area and perimeter of the rectangle)."""
        u0, v0, u1, v1 = (float(b) for b in bbox)
        w, h = u1 - u0, v1 - v0
        return cls((u0, v0, u1, v1), w * h, 2.0 * (w + h), ((u0 + u1) / 2, v1), score, label)


class MotionDetector(Protocol):
    """What every detector does: the blobs of one frame, frames fed in order."""

    def detect(self, frame: Frame) -> list[Blob]:
        """The blobs of ``frame`` (frames must arrive in time order)."""
        ...


def load_mask(path: str, size: tuple[int, int]) -> np.ndarray:
    """An ignore mask from a PNG (white = ignore), resized to ``size`` ``(w, h)``.

    Returns
    -------
    ndarray of bool, shape (h, w)
        True where detections are ignored.
    """
    from ..errors import VideoError

    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise VideoError(f"cannot read mask {path} (a PNG, white = ignore)")
    mask = prepare_mask(img > 127, size)
    if mask is None:  # cannot happen: a mask was given
        raise VideoError(f"cannot read mask {path}")
    return mask


def prepare_mask(mask: np.ndarray | None, size: tuple[int, int]) -> np.ndarray | None:
    """A boolean ``(h, w)`` ignore mask at ``size`` ``(w, h)`` (nearest-neighbour resize)."""
    if mask is None:
        return None
    m = np.asarray(mask).astype(bool)
    w, h = size
    if m.shape != (h, w):
        m = cv2.resize(m.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    return m


@dataclass(frozen=True, eq=False)
class Component:
    """One connected foreground region at the processing resolution.

    ``rect`` is ``(x, y, w, h)`` (OpenCV's bounding rectangle, pixels); ``roi`` the
    uint8 mask of the region inside it (1 = the region); ``area`` its pixel count and
    ``perimeter`` its outer contour's length (pixel centres), both processing pixels.
    """

    rect: tuple[int, int, int, int]
    roi: np.ndarray
    area: float
    perimeter: float


def components(fg: np.ndarray, min_area: float = 0.0) -> list[Component]:
    """The outer regions of a uint8 mask (8-connected outer contours), at least ``min_area``.

    A region is traced by its outer contour (``cv2.findContours``, ``RETR_EXTERNAL``): far
    cheaper than labelling every pixel of a 1280x720 frame, and a region inside another's
    hole belongs to the outer one.
    """
    contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    out = []
    for c in contours:
        x, y, w, h = cv2.boundingRect(c)
        if w * h < min_area:
            continue
        roi = np.zeros((h, w), np.uint8)
        cv2.drawContours(roi, [c], 0, 1, thickness=-1, offset=(-x, -y))
        roi &= fg[y : y + h, x : x + w] > 0
        area = float(cv2.countNonZero(roi))
        if area < min_area:
            continue
        out.append(Component((x, y, w, h), roi, area, float(cv2.arcLength(c, True))))
    return out


def blobs_from_mask(
    fg: np.ndarray,
    *,
    min_area_px: float | np.ndarray,
    scale: float = 1.0,
    keep: Callable[[list[Component]], list[bool]] | None = None,
) -> list[Blob]:
    """Connected regions of a uint8 foreground mask as blobs.

    Parameters
    ----------
    fg : ndarray of uint8, shape (h, w)
        Non-zero = foreground, at the processing resolution.
    min_area_px : float or ndarray
        Smaller regions (in full-frame pixels) are dropped; an array (the shape of
        ``fg``) gives the minimum per pixel, looked up at each region's foot (its
        bottom row, centre column).
    scale : float
        Full-frame pixels per processing pixel (2 when the model ran at half size).
    keep : callable, optional
        ``keep(components)`` -> one bool per :class:`Component`: only those kept become
        blobs.
    """
    s2 = scale * scale
    if isinstance(min_area_px, np.ndarray):  # per foot pixel
        comps = [
            c
            for c in components(fg, float(min_area_px.min()) / s2)
            if c.area * s2 >= min_area_px[c.rect[1] + c.rect[3] - 1, c.rect[0] + c.rect[2] // 2]
        ]
    else:
        comps = components(fg, min_area_px / s2)
    flags = [True] * len(comps) if keep is None else keep(comps)
    return [blob_of(c, scale) for c, ok in zip(comps, flags, strict=True) if ok]


def blob_of(c: Component, scale: float = 1.0) -> Blob:
    """The full-frame blob of a component (box edges at pixel-centre +- 0.5)."""
    x, y, w, h = c.rect
    u0, v0 = x * scale - 0.5, y * scale - 0.5
    u1, v1 = (x + w) * scale - 0.5, (y + h) * scale - 0.5
    return Blob(
        (u0, v0, u1, v1),
        c.area * scale * scale,
        max(c.perimeter, 1.0) * scale,
        ((u0 + u1) / 2.0, v1),
    )
