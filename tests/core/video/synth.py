"""Synthetic test videos written with PyAV, with their true boxes.

A textured static background (smoothed noise, seeded), per-frame sensor noise, a slow
illumination drift, and moving shapes: a person (a tall body with a head) and a car (a
long low body with a cabin). Boxes are demtrack pixels ((0, 0) the centre of the top-left
pixel), the tight box of the drawn shape.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np

START = 1_794_995_200.0  # 2026-11-18T09:46:40Z, the clips' creation_time


@dataclass
class Mover:
    kind: str  # "human" or "vehicle"
    xy0: tuple[float, float]  # top-left at frame 0 (px)
    velocity: tuple[float, float]  # px per frame
    size: tuple[int, int]  # (w, h) px
    grey: int = 40
    stops: tuple[tuple[int, int], ...] = ()  # (first, last) frames standing still
    hidden: tuple[int, int] | None = None  # frames not drawn (occluded)

    def position(self, k: int) -> tuple[float, float]:
        moving = k
        for a, b in self.stops:
            moving -= max(0, min(k, b + 1) - a)
        return self.xy0[0] + self.velocity[0] * moving, self.xy0[1] + self.velocity[1] * moving


def background(w: int, h: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = rng.normal(0, 1, (h // 4 + 1, w // 4 + 1)).astype(np.float32)
    tex = cv2.resize(cv2.GaussianBlur(noise, (0, 0), 1.5), (w, h), interpolation=cv2.INTER_CUBIC)
    tex = (tex - tex.min()) / (np.ptp(tex) + 1e-9)
    return (110 + 80 * tex).astype(np.float32)


def shape_mask(kind: str, w: int, h: int) -> np.ndarray:
    m = np.zeros((h, w), np.uint8)
    if kind == "human":
        r = max(1, w // 3)
        cv2.circle(m, (w // 2, r), r, 1, -1)  # head
        cv2.rectangle(m, (w // 5, 2 * r), (w - 1 - w // 5, int(0.6 * h)), 1, -1)  # torso
        cv2.rectangle(m, (w // 5, int(0.6 * h)), (w // 2 - 1, h - 1), 1, -1)  # legs
        cv2.rectangle(m, (w // 2 + 1, int(0.6 * h)), (w - 1 - w // 5, h - 1), 1, -1)
        cv2.rectangle(m, (0, 2 * r + 1), (w - 1, 2 * r + max(1, h // 12)), 1, -1)  # arms
    else:
        cv2.rectangle(m, (0, h // 3), (w - 1, h - 1), 1, -1)
        cv2.rectangle(m, (w // 4, 0), (3 * w // 4, h // 3), 1, -1)
    return m.astype(bool)


@dataclass
class Clip:
    path: Path
    boxes: list[list[tuple[str, tuple[float, float, float, float]]]] = field(default_factory=list)
    fps: int = 25


def write_video(
    path: Path,
    movers: list[Mover],
    *,
    size: tuple[int, int] = (320, 240),
    n_frames: int = 60,
    fps: int = 25,
    seed: int = 0,
    noise: float = 2.0,
    drift: float = 0.15,
    creation_time: str | None = "2026-11-18T09:46:40.000000Z",
    codec: str = "libx264",
    bg: np.ndarray | None = None,
) -> Clip:
    """Write the clip (H.264, lossless-ish crf 10) and return the true boxes per frame."""
    w, h = size
    base = background(w, h, seed) if bg is None else bg
    rng = np.random.default_rng(seed + 1)
    clip = Clip(path, fps=fps)
    c = av.open(str(path), "w")
    if creation_time:
        c.metadata["creation_time"] = creation_time
    s = c.add_stream(codec, rate=fps)
    s.width, s.height, s.pix_fmt = w, h, "yuv420p"
    s.options = {"crf": "10", "preset": "ultrafast", "bf": "0"}
    for k in range(n_frames):
        img = base + drift * k + rng.normal(0, noise, base.shape).astype(np.float32)
        truth = []
        for m in movers:
            if m.hidden and m.hidden[0] <= k <= m.hidden[1]:
                continue
            x, y = m.position(k)
            xi, yi = int(round(x)), int(round(y))
            mw, mh = m.size
            shp = shape_mask(m.kind, mw, mh)
            x0, y0, x1, y1 = max(xi, 0), max(yi, 0), min(xi + mw, w), min(yi + mh, h)
            if x1 <= x0 or y1 <= y0:
                continue
            sub = shp[y0 - yi : y1 - yi, x0 - xi : x1 - xi]
            region = img[y0:y1, x0:x1]
            region[sub] = m.grey + rng.normal(0, noise, int(sub.sum()))
            rows, cols = np.nonzero(sub)
            truth.append(
                (
                    m.kind,
                    (
                        x0 + cols.min() - 0.5,
                        y0 + rows.min() - 0.5,
                        x0 + cols.max() + 0.5,
                        y0 + rows.max() + 0.5,
                    ),
                )
            )
        clip.boxes.append(truth)
        rgb = np.repeat(np.clip(img, 0, 255).astype(np.uint8)[:, :, None], 3, axis=2)
        frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
        frame.pts = k
        frame.time_base = Fraction(1, fps)
        for p in s.encode(frame):
            c.mux(p)
    for p in s.encode():
        c.mux(p)
    c.close()
    return clip


def iou(a, b) -> float:
    iw = min(a[2], b[2]) - max(a[0], b[0])
    ih = min(a[3], b[3]) - max(a[1], b[1])
    if iw <= 0 or ih <= 0:
        return 0.0
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def match(truth_boxes, found_boxes, thr: float = 0.5) -> tuple[int, int, int]:
    """Greedy one-to-one matching at IoU >= thr: (true positives, n_truth, n_found)."""
    used = set()
    tp = 0
    for t in truth_boxes:
        best, bj = 0.0, None
        for j, f in enumerate(found_boxes):
            if j not in used and (v := iou(t, f)) > best:
                best, bj = v, j
        if bj is not None and best >= thr:
            used.add(bj)
            tp += 1
    return tp, len(truth_boxes), len(found_boxes)


@dataclass
class Body:
    """A box-shaped body on the ground of a site: a person or a car seen by a camera."""

    kind: str
    start_px: tuple[float, float]  # the pixel of its foot at frame 0
    velocity_enu: tuple[float, float]  # m/s east, north
    dims_m: tuple[float, float, float]  # width, length (along the velocity), height
    grey: int = 40
    frames: tuple[int, int] = (0, 10**9)  # drawn in these frames (first, last) only


def body_polygon(camera, p_enu, velocity, dims):
    """Image polygon (convex hull of the projected box corners) of a body at ``p_enu``."""
    w, length, h = dims
    vx, vy = velocity
    n = float(np.hypot(vx, vy)) or 1.0
    along = np.array([vx / n, vy / n, 0.0])
    across = np.array([-along[1], along[0], 0.0])
    corners = [
        p_enu + a * along * length / 2 + c * across * w / 2 + np.array([0, 0, z])
        for a in (-1, 1)
        for c in (-1, 1)
        for z in (0.0, h)
    ]
    u, v, _ = camera.project(np.array(corners))
    return cv2.convexHull(np.stack([u, v], axis=1).astype(np.float32))


def site_clip(path, site, sensor_id, bodies, *, n_frames=60, fps=25, seed=0, noise=2.0):
    """A clip of the site's still image for ``sensor_id`` with bodies moving over the DEM.

    Returns the Clip (true boxes per frame: the bounding box of the drawn hull).
    """
    cam = site.sensor(sensor_id).camera
    geo = site.geolocator()
    bg = cv2.cvtColor(cv2.imread(str(site.sensor(sensor_id).image_path)), cv2.COLOR_BGR2GRAY)
    base = bg.astype(np.float32)
    starts = []
    for b in bodies:
        (loc,) = geo.geolocate(cam, [b.start_px[0]], [b.start_px[1]])
        starts.append(loc.best.p_enu)
    rng = np.random.default_rng(seed)
    h, w = base.shape
    bank = rng.normal(0, noise, (7, h, w)).astype(np.float32)  # sensor noise, cycled
    clip = Clip(Path(path), fps=fps)
    c = av.open(str(path), "w")
    c.metadata["creation_time"] = "2026-11-18T09:46:40.000000Z"
    s = c.add_stream("libx264", rate=fps)
    s.width, s.height, s.pix_fmt = w, h, "yuv420p"
    s.options = {"crf": "12", "preset": "ultrafast", "bf": "0"}
    for k in range(n_frames):
        img = base + bank[k % 7]
        truth = []
        for b, p0 in zip(bodies, starts, strict=True):
            if not b.frames[0] <= k <= b.frames[1]:
                continue
            p = p0 + np.array([b.velocity_enu[0], b.velocity_enu[1], 0.0]) * k / fps
            hull = body_polygon(cam, p, b.velocity_enu, b.dims_m)
            pts = np.round(hull).astype(np.int32)
            x0, y0 = np.maximum(pts.reshape(-1, 2).min(axis=0), 0)
            x1, y1 = np.minimum(pts.reshape(-1, 2).max(axis=0) + 1, (w, h))
            if x1 <= x0 or y1 <= y0:
                continue
            mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
            cv2.fillConvexPoly(mask, pts - np.array([x0, y0]), 1)
            sel = mask.astype(bool)
            if not sel.any():
                continue
            region = img[y0:y1, x0:x1]
            region[sel] = b.grey + rng.normal(0, noise, int(sel.sum()))
            rows, cols = np.nonzero(sel)
            box = (x0 + cols.min() - 0.5, y0 + rows.min() - 0.5)
            truth.append((b.kind, (*box, x0 + cols.max() + 0.5, y0 + rows.max() + 0.5)))
        clip.boxes.append(truth)
        rgb = np.repeat(np.clip(img, 0, 255).astype(np.uint8)[:, :, None], 3, axis=2)
        frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
        frame.pts = k
        frame.time_base = Fraction(1, fps)
        for pkt in s.encode(frame):
            c.mux(pkt)
    for pkt in s.encode():
        c.mux(pkt)
    c.close()
    return clip


def klv_clip(path, datalinks, *, size=(1280, 720), fps=25) -> Path:
    """An MPEG-TS of plain grey H.264 frames with one ST 0601 packet per frame (PTS alike)."""
    from demtrack.core.video.klv import encode_uas_datalink

    w, h = size
    c = av.open(str(path), "w", format="mpegts")
    v = c.add_stream("libx264", rate=fps)
    v.width, v.height, v.pix_fmt = w, h, "yuv420p"
    data = c.add_data_stream("klv")
    for k, d in enumerate(datalinks):
        f = av.VideoFrame.from_ndarray(np.full((h, w, 3), 90, np.uint8), format="rgb24")
        f.pts, f.time_base = k, Fraction(1, fps)
        for p in v.encode(f):
            c.mux(p)
        pkt = av.Packet(encode_uas_datalink(d))
        pkt.stream = data
        pkt.pts = pkt.dts = k * (90000 // fps)
        pkt.time_base = Fraction(1, 90000)
        c.mux(pkt)
    for p in v.encode():
        c.mux(p)
    c.close()
    return Path(path)
