"""The VSAM motion detector: adaptive background subtraction checked by frame differencing.

After Lipton, Fujiyoshi and Patil (1998), "Moving target classification and tracking from
real-time video", and the hybrid of the VSAM final report (Collins et al. 2000, sec. 3.1):

- **Three-frame differencing** marks a pixel as *moving* when it differs from both of
  the two previous frames: ``|I_n - I_{n-1}| > T`` and ``|I_n - I_{n-2}| > T``. It
  never fires on a region that is merely different from an old background (a *ghost*).
- **An adaptive background model** per pixel, a running mean ``mu`` and variance
  ``var`` with learning rate ``alpha``, updated only where the pixel is background
  (``mu += alpha (I - mu)``, ``var += alpha ((I - mu)^2 - var)``), gives the *whole*
  object: foreground where ``|I - mu| > T``, ``T = max(k sigma, min_diff)``. Slow
  illumination drift is learnt at the background pixels.
- **The hybrid**: a foreground component (after a 3x3 median (majority) filter and a
  closing) is kept when it holds moving pixels, or when it overlaps a box kept in the
  previous frame that moved within ``hold_s`` (a stopped object stays detected that
  long). A component not kept (a ghost, or an object still for longer) is learnt into
  the background at once; any pixel foreground and motionless for ``absorb_s`` is too.
  A plain background model (``validate=False``: the mean learns at every pixel, the
  usual running average) keeps every foreground component, ghosts included.
- **Restless background**: a per-pixel motion rate (the share of recent frames in which
  the pixel was moving, time constant ``restless_s``) marks swaying tree crowns and the
  like; a component whose moving pixels move more often than ``restless`` is not an
  object. A target crosses a pixel once, so its rate stays low.
- **Ghosts of departed objects**: where a region is learnt into the background (a
  stopped object after ``hold_s``, a long-still pixel), the background it replaced is
  kept; a foreground pixel that matches that older background again is where the object
  stood and has gone: it is background at once (the mean takes the image, the old value
  is dropped), before components are formed, so no box stays on the empty place.
- **Calm background**: three-frame motion counts only where the learnt background is
  calm (every sigma within 4 px at most ``calm_factor`` times the scene's median sigma,
  the camera's noise). A crown's texture and outline give its pixels sigmas 3-10 times
  the noise even where a gust sways it into pixels of low motion rate; a component
  whose moving pixels all lie there has no evidence of an object and is learnt into
  the background like a ghost. A target over the grass or a road is over calm pixels.
- Components below ``min_area_px`` and pixels under the ignore mask are dropped.

The per-pixel work is OpenCV primitives (``cv2.absdiff``, ``cv2.compare``,
``cv2.accumulateWeighted``; the frame differences on uint8, the background on float32),
about 0.5-1 ms a 1280x720 frame each here; components are traced by their outer
contours, not by labelling every pixel. ``downscale`` (default 1:
full resolution) runs the model on a smaller image when a frame is too big for real time;
blobs come back in full-frame pixels either way.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..errors import VideoError
from .blobs import Blob, Component, MotionDetector, blobs_from_mask, prepare_mask
from .reader import Frame

__all__ = ["Blob", "MotionDetector", "VsamDetector", "iou"]


def iou(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Intersection over union of two ``(u_min, v_min, u_max, v_max)`` boxes."""
    iw = min(a[2], b[2]) - max(a[0], b[0])
    ih = min(a[3], b[3]) - max(a[1], b[1])
    if iw <= 0 or ih <= 0:
        return 0.0
    inter = iw * ih
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def _gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


class VsamDetector:
    """Lipton et al.'s moving-object detector (see the module docstring).

    Parameters
    ----------
    size : tuple of int
        Frame size ``(width, height)`` (px).
    learning_rate : float
        ``alpha`` of the background mean and variance (per frame, 0..1).
    threshold_sigma : float
        ``k``: a pixel is foreground (and moving) beyond ``k`` of its standard deviations.
    min_diff : float
        Floor of the threshold (grey levels), against a variance learnt too small.
    min_area_px : float
        Blobs smaller than this (full-frame pixels) are dropped.
    mask : ndarray of bool, optional
        ``(h, w)`` ignore mask (True = ignore), any size (resized).
    fps : float
        Frame rate, for ``absorb_s``.
    absorb_s : float
        A foreground region with no motion for this long is learnt into the background.
    restless : float
        A component whose pixels moved, on average, in more than this share of the
        recent frames is restless background (a tree crown in the wind, rippling water):
        not an object. 1 turns the test off.
    restless_s : float
        Time constant of that per-pixel motion rate (s).
    calm_factor : float
        A pixel's motion is evidence of an object only where the background is calm:
        its learnt sigma, and every sigma within 4 px of it, at most this many times the
        scene's median sigma (the camera's noise). Swaying crowns are learnt with large
        variances (their texture and outline flicker at the edge of the model); motion
        there is the crown's. 0 turns the test off.
    hold_s : float
        A kept object that stops is still reported this long after its last motion;
        then (and any foreground region never validated by motion, a ghost) it is learnt
        into the background at once.
    validate : bool
        Keep only components validated by three-frame differencing (the hybrid); False
        is a plain adaptive background subtraction (for comparison).
    downscale : int
        Run the model on an image this many times smaller (1 = full resolution).
    """

    def __init__(
        self,
        size: tuple[int, int],
        *,
        learning_rate: float = 0.05,
        threshold_sigma: float = 4.0,
        min_diff: float = 10.0,
        min_area_px: float = 16.0,
        mask: np.ndarray | None = None,
        fps: float = 25.0,
        absorb_s: float = 10.0,
        hold_s: float = 5.0,
        restless: float = 0.12,
        restless_s: float = 10.0,
        calm_factor: float = 3.0,
        validate: bool = True,
        downscale: int = 1,
    ) -> None:
        w, h = (int(s) for s in size)
        if w < 8 or h < 8:
            raise VideoError(f"frame size must be at least 8x8, got {size}")
        if not 0 < learning_rate < 1:
            raise VideoError(f"learning_rate must be within (0, 1), got {learning_rate}")
        for name, value in (
            ("threshold_sigma", threshold_sigma),
            ("min_diff", min_diff),
            ("fps", fps),
            ("absorb_s", absorb_s),
            ("hold_s", hold_s),
        ):
            if not (math.isfinite(value) and value > 0):
                raise VideoError(f"{name} must be positive, got {value}")
        if int(downscale) < 1:
            raise VideoError(f"downscale must be 1 or more, got {downscale}")
        self.size = (w, h)
        self.scale = int(downscale)
        self.work_size = (w // self.scale, h // self.scale)
        self.alpha = float(learning_rate)
        self.k = float(threshold_sigma)
        self.min_diff = float(min_diff)
        self.min_area_px = float(min_area_px)
        self.min_area: float | np.ndarray = self.min_area_px  # or a map, set_min_area_map
        self.validate = bool(validate)
        self.absorb_frames = max(1, int(round(absorb_s * fps)))
        full_mask = prepare_mask(mask, self.size)
        self.mask = None if full_mask is None else prepare_mask(full_mask, self.work_size)
        self._keep_mask = (
            None if self.mask is None else np.where(self.mask, 0, 255).astype(np.uint8)
        )
        self._open = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))
        self._close = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
        self._mu: np.ndarray | None = None
        self._var: np.ndarray | None = None
        self._prev: list[np.ndarray] = []  # I_{n-1}, I_{n-2} (uint8)
        self._thr: tuple[np.ndarray, np.ndarray] | None = None
        self.calm_factor = float(calm_factor)
        self._calm: np.ndarray | None = None  # 255 where the background is calm
        self._calm_kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (9, 9))  # 4 px
        self._still = np.zeros(self.work_size[::-1], np.uint16)  # frames fg without motion
        self._one16 = np.ones_like(self._still)
        self._kept: list[tuple[float, float, float, float]] = []
        self._last_motion: list[int] = []  # frame of each kept box's last motion
        self._stamps: list[int] = []
        self.hold_frames = max(1, int(round(hold_s * fps)))
        self._check_every = max(1, int(round(fps)))
        self.restless = float(restless) * 255.0
        self._fps = float(fps)
        self._activity_rate = min(1.0, 1.0 / max(restless_s * fps, 1.0))
        self._activity = np.zeros(self.work_size[::-1], np.float32)  # 255 x motion rate
        # the background each absorbed pixel had before it was absorbed (see _absorb)
        self._mu_old = np.zeros(self.work_size[::-1], np.float32)
        self._absorbed = np.zeros(self.work_size[::-1], np.uint8)  # 255 where mu_old holds
        self._n_absorbed = 0
        self.n_frames = 0

    def set_min_area_map(self, min_area_px: np.ndarray) -> None:
        """Make the minimum blob area a function of the foot pixel.

        ``min_area_px`` : ``(h, w)`` full-frame minimum areas (full-frame pixels) by
        foot pixel, e.g. :func:`~.scale.min_area_map` of the person's size there.
        """
        m = np.asarray(min_area_px, dtype=np.float32)
        if m.shape != self.size[::-1] or not np.isfinite(m).all() or (m < 1).any():
            raise VideoError(f"min_area_px must be a finite (h, w) = {self.size[::-1]} map >= 1")
        if self.scale > 1:
            m = np.asarray(cv2.resize(m, self.work_size, interpolation=cv2.INTER_AREA), np.float32)
        self.min_area = np.ascontiguousarray(m)

    def _prepare(self, image: np.ndarray) -> np.ndarray:
        g = _gray(image)
        if g.shape[::-1] != self.size:
            raise VideoError(f"frame is {g.shape[1]}x{g.shape[0]}, detector expects {self.size}")
        if self.scale > 1:
            g = cv2.resize(g, self.work_size, interpolation=cv2.INTER_AREA)
        return np.ascontiguousarray(g, dtype=np.uint8)

    def _thresholds(self) -> tuple[np.ndarray, np.ndarray]:
        """``T = max(k sigma, min_diff)`` as float32, and as uint8 ``floor(T)``.

        The uint8 form serves the uint8 frame differences (an integer difference exceeds
        ``T`` exactly when it exceeds ``floor(T)``). Refreshed every 4 frames: the
        variance moves slowly.
        """
        if (self._thr is None or self.n_frames % 4 == 0) and self._var is not None:
            thr: np.ndarray = np.asarray(cv2.sqrt(self._var), dtype=np.float32)
            np.multiply(thr, np.float32(self.k), out=thr)  # in place: no temporaries
            np.maximum(thr, np.float32(self.min_diff), out=thr)
            thr8 = np.floor(np.minimum(thr, 255.0)).astype(np.uint8)
            self._thr = (thr, thr8)
            if self.calm_factor > 0:
                # sigma <= calm_factor x the scene's median sigma (its noise floor), as a
                # threshold: k sigma <= k calm_factor median
                floor = float(np.median(thr[::8, ::8])) / self.k
                limit = max(self.k * self.calm_factor * floor, self.min_diff)
                calm = np.where(thr <= limit, np.uint8(255), np.uint8(0))
                self._calm = cv2.erode(calm, self._calm_kernel)
        if self._thr is None:
            raise VideoError("no background model yet")
        return self._thr

    def detect(self, frame: Frame) -> list[Blob]:
        """The moving blobs of ``frame`` (none for the first two frames: warm-up)."""
        g8 = self._prepare(frame.image)
        img = g8.astype(np.float32)
        self.n_frames += 1
        if self._mu is None or self._var is None:
            self._mu = img.copy()
            self._var = np.full_like(img, (self.min_diff / self.k) ** 2)
            self._prev = [g8]
            return []
        mu = self._mu
        thr, thr8 = self._thresholds()
        diff_bg = cv2.absdiff(img, mu)
        fg = cv2.compare(diff_bg, thr, cv2.CMP_GT)
        if self._n_absorbed:
            self._restore_departed(img, thr, fg, diff_bg)
        if len(self._prev) == 2:  # three-frame differencing on the uint8 frames
            m1 = cv2.compare(cv2.absdiff(g8, self._prev[0]), thr8, cv2.CMP_GT)
            m2 = cv2.compare(cv2.absdiff(g8, self._prev[1]), thr8, cv2.CMP_GT)
            moving = cv2.bitwise_and(m1, m2)
        else:
            moving = np.zeros_like(fg)
        if self._keep_mask is not None:
            fg = cv2.bitwise_and(fg, self._keep_mask)
            moving = cv2.bitwise_and(moving, self._keep_mask)
        self._prev = [g8, self._prev[0]]
        # learnt faster at the start (a mean over the frames so far plus a second's worth),
        # so swaying crowns are known within about a second of the first frame
        rate = max(self._activity_rate, 1.0 / (self.n_frames + self._fps))
        cv2.accumulateWeighted(moving, self._activity, rate)
        if self._calm is not None:  # motion over a restless background is no evidence
            moving = cv2.bitwise_and(moving, self._calm)
        self._update(img, diff_bg, fg, moving)
        if self.n_frames < 3:
            return []
        # a 3x3 majority (median) filter: drops isolated noise pixels and 1-px slivers but
        # keeps a far person two pixels wide, which a 3x3 opening would erase
        clean = cv2.medianBlur(fg, 3)
        clean = cv2.morphologyEx(clean, cv2.MORPH_CLOSE, self._close)
        if self._keep_mask is not None:
            clean = cv2.bitwise_and(clean, self._keep_mask)
        if not self.validate:
            blobs = blobs_from_mask(clean, min_area_px=self.min_area, scale=self.scale)
            self._kept = [b.bbox for b in blobs]
            return blobs
        state: dict = {}
        keep = self._validator(moving, state)
        blobs = blobs_from_mask(clean, min_area_px=self.min_area, scale=self.scale, keep=keep)
        self._kept = [b.bbox for b in blobs]
        self._last_motion = state["stamps"]
        for c in state["rejected"]:  # ghosts and long-still regions: learn them now
            x, y, w, h = c.rect
            sel = np.zeros(mu.shape, bool)
            sel[y : y + h, x : x + w] = c.roi.astype(bool)
            self._absorb(sel, img, keep_old=id(c) not in state["restless_ids"])
            self._still[sel] = 0
        return blobs

    def _absorb(self, sel: np.ndarray, img: np.ndarray, keep_old: bool = True) -> None:
        """Learn the pixels ``sel`` (bool, work size) into the background at once.

        With ``keep_old`` the background they had is kept (where none is kept yet), so
        that :meth:`_restore_departed` knows the place again once the object leaves.
        """
        mu = self._mu
        if mu is None:
            return
        if keep_old:
            new = sel & (self._absorbed == 0)
            if new.any():
                self._mu_old[new] = mu[new]
                self._absorbed[new] = 255
                self._n_absorbed += int(new.sum())
        mu[sel] = img[sel]

    def _restore_departed(
        self, img: np.ndarray, thr: np.ndarray, fg: np.ndarray, diff_bg: np.ndarray
    ) -> None:
        """Foreground pixels that match their pre-absorption background: background again.

        Updates ``fg`` (to 0) and ``diff_bg`` there, the mean (to the image) and drops the
        old background of those pixels.
        """
        mu = self._mu
        if mu is None:
            return
        same = cv2.compare(cv2.absdiff(img, self._mu_old), thr, cv2.CMP_LE)
        back = cv2.bitwise_and(cv2.bitwise_and(same, self._absorbed), fg)
        if not cv2.countNonZero(back):
            return
        sel = back.astype(bool)
        mu[sel] = img[sel]
        diff_bg[sel] = 0.0
        fg[sel] = 0
        self._absorbed[sel] = 0
        self._n_absorbed = max(0, self._n_absorbed - int(sel.sum()))

    def _validator(self, moving: np.ndarray, state: dict):
        """``keep`` for :func:`blobs_from_mask` (the hybrid rule of the module docstring).

        A component is kept if it holds moving pixels; or, still, if it overlaps a box
        kept in the previous frame that moved within ``hold_s`` and that no moving
        component overlaps now (a component split off a moving one is a ghost).
        """
        s, n = self.scale, self.n_frames
        previous, last_motion = self._kept, self._last_motion

        def keep(comps: list[Component]) -> list[bool]:
            boxes, is_moving = [], []
            restless = []
            for c in comps:
                x, y, w, h = c.rect
                boxes.append((x * s - 0.5, y * s - 0.5, (x + w) * s - 0.5, (y + h) * s - 0.5))
                roi_moving = cv2.bitwise_and(
                    moving[y : y + h, x : x + w], moving[y : y + h, x : x + w], mask=c.roi
                )
                n_moving = cv2.countNonZero(roi_moving)
                is_moving.append(n_moving > 0)
                # the motion rate where it moves now (a crown flickers at the same pixels;
                # a target's edges are new pixels); where still, over the whole region
                where = roi_moving if n_moving else c.roi
                rate = cv2.mean(self._activity[y : y + h, x : x + w], mask=where)[0]
                restless.append(rate > self.restless)
            claimed = {
                i
                for i, b in enumerate(previous)
                for box, mv in zip(boxes, is_moving, strict=True)
                if mv and iou(box, b) > 0.0
            }
            out, stamps, rejected = [], [], []
            state["restless_ids"] = set()
            for c, box, mv, rl in zip(comps, boxes, is_moving, restless, strict=True):
                if rl:  # restless background: no object, learnt into the background
                    out.append(False)
                    rejected.append(c)
                    state["restless_ids"].add(id(c))
                    continue
                if mv:
                    out.append(True)
                    stamps.append(n)
                    continue
                last = max(
                    (
                        last_motion[i]
                        for i, b in enumerate(previous)
                        if i not in claimed and iou(box, b) >= 0.3
                    ),
                    default=-1,
                )
                ok = last >= 0 and n - last <= self.hold_frames
                out.append(ok)
                if ok:
                    stamps.append(last)
                elif not any(
                    mv2 and iou(box, b2) > 0.0 for b2, mv2 in zip(boxes, is_moving, strict=True)
                ):
                    # learnt at once, unless it touches a moving object's box: a still
                    # piece of a big uniform body (its roof) must not become background
                    rejected.append(c)
            state["stamps"], state["rejected"] = stamps, rejected
            return out

        return keep

    def _update(
        self, img: np.ndarray, diff_bg: np.ndarray, fg: np.ndarray, moving: np.ndarray
    ) -> None:
        """Learn the background where the pixel is background (the mean everywhere if plain)."""
        mu, var = self._mu, self._var
        if mu is None or var is None:
            return
        sq = cv2.multiply(diff_bg, diff_bg)
        background = cv2.bitwise_not(fg)
        if not self.validate:  # the plain model of the comparison: the mean learns everywhere
            cv2.accumulateWeighted(img, mu, self.alpha)
            cv2.accumulateWeighted(sq, var, self.alpha, mask=background)
            return
        cv2.accumulateWeighted(img, mu, self.alpha, mask=background)
        cv2.accumulateWeighted(sq, var, self.alpha, mask=background)
        # Frames each pixel has been foreground without moving (reset by motion or by
        # being background); checked once a second, a pixel still for absorb_s is learnt.
        still = cv2.bitwise_and(fg, cv2.bitwise_not(moving))
        grown = cv2.add(self._still, self._one16)
        self._still = cv2.bitwise_and(grown, grown, mask=still)  # 0 where not still
        if self.n_frames % self._check_every == 0:
            absorbed = self._still >= self.absorb_frames
            if absorbed.any():
                self._absorb(absorbed, img)
                self._still[absorbed] = 0
