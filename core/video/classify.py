"""Classifying blobs: human, vehicle or clutter, from shape and from size in metres.

Lipton et al. (1998) classify a blob from its **dispersedness** ``perimeter^2 / area``
(a person's outline is more complex than a car's: they report humans well above
vehicles) and its **area**, and make the label stick by a vote over the blob's history
(:mod:`.blob_tracker`). Area in pixels depends on range; we know the range. The blob's
foot pixel (bottom-centre) is geolocated on the site's DEM, and the box's width and
height are turned into metres at that point:

- height: the height ``z`` above the foot at which the vertical through the foot point
  projects to the box's top row (exact under the camera model, any tilt);
- width: the box width over the image scale at the foot, the projection of a 1 m
  horizontal segment across the line of sight.

Each blob is scored against size prototypes in log-space (a ratio error is what matters):
a person 0.6 m wide, 1.7 m tall (adult stature 1.5-1.9 m, shoulder width 0.4-0.5 m plus
the stride; ANSUR II); a car side-on 4.5 m x 1.5 m, end-on 1.8 m x 1.5 m, at 45 degrees
4.4 m wide (a typical European passenger car: length 4.2-4.8 m, width 1.75-1.85 m,
height 1.45-1.55 m). The
prototype's height is compared as it appears from the camera (:func:`apparent_height_m`:
from above, the top of a deep body lies beyond the foot and looks higher). The
prototype spread ``size_sigma`` 0.35 in log units (+-42 % at 1 sigma) covers children,
vans, partial occlusion and box slack. Farther than ``clutter_sigma`` from every
prototype is clutter (a swaying crown, a shadow, a bird). Without a camera and DEM the
classifier falls back to Lipton's image cues: box aspect (taller than wide: human) and
dispersedness.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import VideoError
from .blobs import Blob

__all__ = [
    "CLUTTER",
    "apparent_height_m",
    "PROTOTYPES",
    "BlobClass",
    "BlobClassifier",
    "dispersedness",
]

CLUTTER = "clutter"

#: (class, width_m, height_m, depth_m): the size prototypes (see the module docstring);
#: depth is the extent along the line of sight (a car side-on is 1.8 m deep, end-on
#: 4.5 m, at 45 degrees 4.4 m wide and deep).
PROTOTYPES: tuple[tuple[str, float, float, float], ...] = (
    ("human", 0.6, 1.7, 0.4),
    ("vehicle", 4.5, 1.5, 1.8),
    ("vehicle", 1.8, 1.5, 4.5),
    ("vehicle", 4.4, 1.5, 4.4),
)


def apparent_height_m(height_m: float, depth_m: float, above_m: float, reach_m: float) -> float:
    """The height on the foot point's vertical that a box of this depth appears to have.

    Seen from ``above_m`` over the foot at horizontal range ``reach_m``, the far top edge
    of a body ``depth_m`` deep and ``height_m`` tall lies on the ray that crosses the
    foot's vertical at ``above - (above - height) * reach / (reach + depth)``: a car seen
    from above looks taller than it is by its roof's depth (a level view: its height).
    """
    if above_m <= height_m or reach_m <= 0:
        return height_m
    return above_m - (above_m - height_m) * reach_m / (reach_m + depth_m)


def dispersedness(perimeter_px: float, area_px: float) -> float:
    """Lipton et al.'s dispersedness ``perimeter^2 / area`` (4 pi for a disc, 16 for a square)."""
    if not area_px > 0:
        raise VideoError(f"area must be positive, got {area_px}")
    return float(perimeter_px) ** 2 / float(area_px)


@dataclass(frozen=True)
class BlobClass:
    """A blob's class for one frame, with what it was decided from.

    ``cls`` is ``human``, ``vehicle`` or ``clutter``; ``score`` in 0..1 (1: on a
    prototype); ``width_m`` / ``height_m`` the metric size (NaN without geometry);
    ``foot_enu`` the geolocated foot point (site frame, m), or None.
    """

    cls: str
    score: float
    width_m: float = math.nan
    height_m: float = math.nan
    foot_enu: tuple[float, float, float] | None = None


class BlobClassifier:
    """Classify blobs by size at their geolocated foot point (or by shape alone).

    Parameters
    ----------
    camera : Camera, optional
        The blob's camera (``project``, ``pixel_to_ray``, ``position_enu``).
    geolocator : Geolocator, optional
        On the site's DEM; with ``camera`` it enables metric sizes.
    size_sigma : float
        Prototype spread in natural-log units.
    clutter_sigma : float
        Farther than this many sigmas from every prototype is clutter.
    min_dispersedness_human : float
        Image-only fallback: a blob taller than wide and at least this dispersed is human.
    """

    def __init__(
        self,
        camera: Any | None = None,
        geolocator: Any | None = None,
        *,
        size_sigma: float = 0.35,
        clutter_sigma: float = 3.0,
        min_dispersedness_human: float = 14.0,
    ) -> None:
        if (camera is None) != (geolocator is None):
            raise VideoError("give both camera and geolocator for metric sizes, or neither")
        self.camera = camera
        self.geolocator = geolocator
        self.size_sigma = float(size_sigma)
        self.clutter_sigma = float(clutter_sigma)
        self.min_dispersedness_human = float(min_dispersedness_human)

    @property
    def metric(self) -> bool:
        """True when sizes are judged in metres."""
        return self.camera is not None

    def classify(self, blobs: Sequence[Blob]) -> list[BlobClass]:
        """One :class:`BlobClass` per blob, in order."""
        if not blobs:
            return []
        if not self.metric:
            return [self._by_shape(b) for b in blobs]
        sizes = self.metric_sizes(blobs)
        out = []
        for w_m, h_m, foot in sizes:
            if foot is None or not (w_m > 0 and h_m > 0):
                out.append(BlobClass(CLUTTER, 0.0, w_m, h_m, foot))
                continue
            out.append(self._by_size(w_m, h_m, foot))
        return out

    def _by_size(self, w_m: float, h_m: float, foot) -> BlobClass:
        # camera height above the foot and horizontal range to it (m)
        cam = np.asarray(self.camera.position_enu, dtype=np.float64)  # type: ignore[union-attr]
        above = float(cam[2] - foot[2])
        reach = float(math.hypot(cam[0] - foot[0], cam[1] - foot[1]))
        best, best_d = CLUTTER, math.inf
        for cls, pw, ph, depth in PROTOTYPES:
            ph_seen = apparent_height_m(ph, depth, above, reach)
            d = math.hypot(math.log(w_m / pw), math.log(h_m / ph_seen)) / self.size_sigma
            if d < best_d:
                best, best_d = cls, d
        if best_d > self.clutter_sigma:
            return BlobClass(CLUTTER, 0.0, w_m, h_m, foot)
        return BlobClass(best, math.exp(-0.5 * best_d**2), w_m, h_m, foot)

    def _by_shape(self, b: Blob) -> BlobClass:
        aspect = b.height_px / max(b.width_px, 1e-9)
        disp = dispersedness(b.perimeter_px, b.area_px)
        if aspect >= 1.2 and disp >= self.min_dispersedness_human:
            return BlobClass("human", min(1.0, aspect / 2.8))
        if aspect < 1.0:
            return BlobClass("vehicle", min(1.0, 1.0 / max(aspect, 0.3) / 3.0))
        return BlobClass(CLUTTER, 0.0)

    def metric_sizes(
        self, blobs: Sequence[Blob]
    ) -> list[tuple[float, float, tuple[float, float, float] | None]]:
        """``(width_m, height_m, foot_enu)`` per blob.

        NaN and None where the foot ray meets no ground.
        """
        cam: Any = self.camera
        geo: Any = self.geolocator
        if cam is None or geo is None:
            raise VideoError("metric sizes need a camera and a geolocator")
        w_img, h_img = cam.intrinsics.width, cam.intrinsics.height
        u = np.array([min(max(b.foot_px[0], -0.5), w_img - 0.5) for b in blobs])
        v = np.array([min(max(b.foot_px[1], -0.5), h_img - 0.5) for b in blobs])
        hits = geo.locate_pixels([(cam, u, v)])
        out: list[tuple[float, float, tuple[float, float, float] | None]] = []
        for i, b in enumerate(blobs):
            lo, hi = int(hits.offsets[i]), int(hits.offsets[i + 1])
            if hi <= lo:
                out.append((math.nan, math.nan, None))
                continue
            p = hits.points_enu[lo]
            out.append(
                (self._width_m(b, p), self._height_m(b, p), (float(p[0]), float(p[1]), float(p[2])))
            )
        return out

    def _height_m(self, b: Blob, p: np.ndarray) -> float:
        """Height above ``p`` whose image is the box's top row (m)."""
        z = np.arange(0.0, 12.01, 0.05)
        pts = np.repeat(p[None, :], z.size, axis=0)
        pts[:, 2] += z
        cam: Any = self.camera
        _, vz, _ = cam.project(pts)
        ok = np.isfinite(vz)
        if ok.sum() < 2:
            return math.nan
        vz, z = vz[ok], z[ok]
        # v decreases up the vertical (image rows grow downwards)
        top = b.bbox[1]
        if top <= vz[-1]:
            return float(z[-1])
        return float(np.interp(top, vz[::-1], z[::-1]))

    def _width_m(self, b: Blob, p: np.ndarray) -> float:
        """Box width over the image scale (px/m) across the line of sight at ``p`` (m)."""
        cam: Any = self.camera
        los = p - np.asarray(cam.position_enu, dtype=np.float64)
        across = np.array([los[1], -los[0], 0.0])
        n = np.linalg.norm(across)
        if n == 0:
            return math.nan
        across /= n
        u, v, _ = cam.project(np.stack([p - 0.5 * across, p + 0.5 * across]))
        px_per_m = math.hypot(u[1] - u[0], v[1] - v[0])
        if not px_per_m > 0:
            return math.nan
        return float(b.width_px / px_per_m)
