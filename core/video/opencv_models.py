"""OpenCV's background subtractors (MOG2, KNN) as :class:`MotionDetector` components.

``cv2.createBackgroundSubtractorMOG2`` (Zivkovic 2004, a per-pixel Gaussian mixture) and
``cv2.createBackgroundSubtractorKNN`` (Zivkovic and van der Heijden 2006) replace the VSAM
model; the same morphology, ignore mask, minimum area and blob extraction follow. Shadows
(MOG2's and KNN's grey 127) are not foreground. Neither validates by frame differencing,
so a departing object that had been learnt leaves a ghost until relearnt.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from ..errors import VideoError
from .blobs import Blob, blobs_from_mask, prepare_mask
from .reader import Frame

__all__ = ["KnnDetector", "Mog2Detector"]


class _OpenCvDetector:
    """Shared body: subtractor -> threshold -> open/close -> mask -> blobs."""

    def __init__(
        self,
        size: tuple[int, int],
        subtractor: Any,
        *,
        min_area_px: float,
        mask: np.ndarray | None,
        learning_rate: float,
    ) -> None:
        w, h = (int(s) for s in size)
        if w < 8 or h < 8:
            raise VideoError(f"frame size must be at least 8x8, got {size}")
        self.size = (w, h)
        self.subtractor = subtractor
        self.min_area_px = float(min_area_px)
        self.learning_rate = float(learning_rate)
        m = prepare_mask(mask, self.size)
        self._keep = None if m is None else np.where(m, 0, 255).astype(np.uint8)
        self._open = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))
        self._close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
        self.n_frames = 0

    def foreground(self, image: np.ndarray) -> np.ndarray:
        """The raw uint8 foreground mask of one frame (255 = foreground)."""
        fg = self.subtractor.apply(image, learningRate=self.learning_rate)
        return cv2.threshold(fg, 200, 255, cv2.THRESH_BINARY)[1]

    def detect(self, frame: Frame) -> list[Blob]:
        """The foreground blobs of ``frame`` (none for the first frame)."""
        img = frame.image
        if img.shape[1::-1] != self.size:
            raise VideoError(
                f"frame is {img.shape[1]}x{img.shape[0]}, detector expects {self.size}"
            )
        fg = self.foreground(img)
        self.n_frames += 1
        if self.n_frames < 2:
            return []
        fg = cv2.morphologyEx(fg, cv2.MORPH_OPEN, self._open)
        fg = cv2.morphologyEx(fg, cv2.MORPH_CLOSE, self._close)
        if self._keep is not None:
            fg = cv2.bitwise_and(fg, self._keep)
        return blobs_from_mask(fg, min_area_px=self.min_area_px)


class Mog2Detector(_OpenCvDetector):
    """OpenCV's MOG2 background subtractor as a detector.

    Parameters
    ----------
    size : tuple of int
        Frame size ``(width, height)``.
    history : int
        Frames of MOG2's history.
    var_threshold : float
        MOG2's squared Mahalanobis threshold.
    learning_rate : float
        Per-frame learning rate (-1: OpenCV's automatic ``1 / history``).
    min_area_px : float
        Smaller blobs are dropped.
    mask : ndarray of bool, optional
        Ignore mask (True = ignore).
    """

    def __init__(
        self,
        size: tuple[int, int],
        *,
        history: int = 500,
        var_threshold: float = 16.0,
        learning_rate: float = -1.0,
        min_area_px: float = 30.0,
        mask: np.ndarray | None = None,
    ) -> None:
        sub = cv2.createBackgroundSubtractorMOG2(
            history=int(history), varThreshold=float(var_threshold), detectShadows=True
        )
        super().__init__(size, sub, min_area_px=min_area_px, mask=mask, learning_rate=learning_rate)


class KnnDetector(_OpenCvDetector):
    """OpenCV's KNN background subtractor as a detector.

    Parameters as :class:`Mog2Detector`; ``dist2_threshold`` is KNN's squared distance
    threshold.
    """

    def __init__(
        self,
        size: tuple[int, int],
        *,
        history: int = 500,
        dist2_threshold: float = 400.0,
        learning_rate: float = -1.0,
        min_area_px: float = 30.0,
        mask: np.ndarray | None = None,
    ) -> None:
        sub = cv2.createBackgroundSubtractorKNN(
            history=int(history), dist2Threshold=float(dist2_threshold), detectShadows=True
        )
        super().__init__(size, sub, min_area_px=min_area_px, mask=mask, learning_rate=learning_rate)
