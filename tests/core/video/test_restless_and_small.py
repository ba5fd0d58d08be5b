"""The detector's calm-background rule and the range-aware minimum area, on small frames.

A swaying crown (a dark textured disc whose outline and texture sway 2-4 px, with gusts)
next to grass, and a slow walker 3 px wide: after the learning period the crown gives no
blob while the walker still does; without the rule the crown's sway is taken for motion.
A far walker 2 px x 7 px is kept where the minimum-area map says a person is that small,
and dropped by the fixed 16 px floor. Frames are built in memory (no codec), 10 Hz.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from demtrack.core.errors import VideoError
from demtrack.core.video.blob_tracker import partial_view
from demtrack.core.video.blobs import blobs_from_mask
from demtrack.core.video.detector import VsamDetector, iou
from demtrack.core.video.reader import Frame
from demtrack.core.video.scale import min_area_map, person_area_map

W, H, FPS = 160, 120, 10.0
LEARN = 150  # 15 s of learning, as the sample videos' lead-in


def _crown_texture(rng: np.random.Generator) -> np.ndarray:
    """A dark crown, 4x supersampled: a textured disc on grass, 200 px square."""
    tex = cv2.GaussianBlur(rng.normal(0, 1, (200, 200)).astype(np.float32), (0, 0), 3)
    tex = 70 + 25 * tex / np.abs(tex).max()
    disc = np.zeros((200, 200), np.float32)
    cv2.circle(disc, (100, 100), 90, 1.0, -1)
    return np.where(disc > 0, tex, np.nan)


def crown_clip(n_frames: int, walker_from: int, seed: int = 0):
    """Frames of a swaying crown left of a walker; the walker's true boxes per frame."""
    rng = np.random.default_rng(seed)
    crown = _crown_texture(rng)
    grass = 150 + 6 * cv2.GaussianBlur(rng.normal(0, 1, (H, W)).astype(np.float32), (0, 0), 2)
    frames, boxes = [], []
    for k in range(n_frames):
        t = k / FPS
        gust = 1.0 + 0.8 * (np.sin(2 * np.pi * t / 9.0) > 0.6)  # a gust every 9 s
        sway = 2.0 * gust * np.sin(2 * np.pi * 0.4 * t)  # px at full size
        shift = np.float32([[1, 0, 4 * (20 + sway)], [0, 1, 4 * 10]])  # 4x supersampled
        big = cv2.warpAffine(
            np.nan_to_num(crown, nan=-1.0), shift, (4 * W, 4 * H), borderValue=-1.0
        )
        inside = cv2.resize((big >= 0).astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
        value = cv2.resize(np.where(big >= 0, big, 0), (W, H), interpolation=cv2.INTER_AREA)
        img = np.where(inside > 0, value + (1 - inside) * grass, grass)
        img = img + rng.normal(0, 2.0, img.shape)
        box = None
        if k >= walker_from:
            x = 100.0 + 0.4 * (k - walker_from)  # 4 px/s: a walker 200 m away
            xi, y0 = int(round(x)), 60
            img[y0 : y0 + 8, xi : xi + 3] = 95 + rng.normal(0, 2.0, (8, 3))
            box = (xi - 0.5, y0 - 0.5, xi + 2.5, y0 + 7.5)
        frames.append(Frame(k, k / FPS, np.clip(img, 0, 255).astype(np.uint8)))
        boxes.append(box)
    return frames, boxes


@pytest.fixture(scope="module")
def clip():
    return crown_clip(LEARN + 120, walker_from=LEARN + 20)


def run(frames, boxes, detector):
    """Crown blobs (ending left of x = 95) and the walker's recall after the learning period."""
    crown = walker = n_walker = 0
    for f, box in zip(frames, boxes, strict=True):
        blobs = detector.detect(f)
        if f.index < LEARN:
            continue
        crown += sum(b.bbox[2] < 95 for b in blobs)
        if box is not None:
            n_walker += 1
            walker += any(iou(b.bbox, box) >= 0.5 for b in blobs)
    return crown, walker / max(n_walker, 1)


def test_a_swaying_crown_gives_no_blob_while_a_slow_walker_does(clip):
    crown, recall = run(*clip, VsamDetector((W, H), fps=FPS))
    assert crown == 0
    assert recall >= 0.9


def test_without_the_calm_rule_the_crown_is_taken_for_motion(clip):
    crown, _ = run(*clip, VsamDetector((W, H), fps=FPS, calm_factor=0))
    assert crown >= 5


def test_the_minimum_area_map_keeps_a_far_walker_the_fixed_floor_drops():
    fg = np.zeros((H, W), np.uint8)
    fg[50:57, 30:32] = 255  # a walker 2 px x 7 px, foot at row 56
    fg[50:57, 120:122] = 255  # the same size nearer the camera
    area = np.full((H, W), 16.0, np.float32)
    area[:, :80] = 6.0  # the left half sees far ground: a person there is small
    blobs = blobs_from_mask(fg, min_area_px=area)
    assert [b.bbox for b in blobs] == [(29.5, 49.5, 31.5, 56.5)]
    assert blobs_from_mask(fg, min_area_px=16.0) == []


def test_a_far_walker_is_detected_with_the_map():
    rng = np.random.default_rng(3)
    grass = 150 + 4 * cv2.GaussianBlur(rng.normal(0, 1, (H, W)).astype(np.float32), (0, 0), 2)
    frames, boxes = [], []
    for k in range(80):
        img = grass + rng.normal(0, 2.0, grass.shape)
        box = None
        if k >= 40:
            xi = int(round(60 + 0.4 * (k - 40)))
            img[40:47, xi : xi + 2] = 100
            box = (xi - 0.5, 39.5, xi + 1.5, 46.5)
        frames.append(Frame(k, k / FPS, np.clip(img, 0, 255).astype(np.uint8)))
        boxes.append(box)

    def hits(det):
        n = 0
        for f, box in zip(frames, boxes, strict=True):
            blobs = det.detect(f)
            n += box is not None and any(iou(b.bbox, box) >= 0.5 for b in blobs)
        return n

    fixed = VsamDetector((W, H), fps=FPS)
    scaled = VsamDetector((W, H), fps=FPS)
    scaled.set_min_area_map(np.full((H, W), 6.0, np.float32))
    # of 40 frames with the walker, 2 x 7 px: the median filter leaves 2 x 5 = 10 px
    assert hits(scaled) >= 30
    assert hits(fixed) == 0


def test_min_area_map_bounds_and_the_sky():
    person = np.array([[np.nan, 2.0], [20.0, 400.0]], np.float32)
    m = min_area_map(person, fraction=0.4, floor_px=4.0, ceil_px=16.0)
    assert m.tolist() == [[16.0, 4.0], [8.0, 16.0]]
    with pytest.raises(VideoError):
        VsamDetector((W, H)).set_min_area_map(np.ones((H, W - 1), np.float32))


def test_person_area_follows_the_inverse_square_of_the_range(sample_site_dir):
    from demtrack.core.site.folder import load_site

    site = load_site(sample_site_dir)
    cam, geo = site.sensor("cam3").camera, site.geolocator()
    area = person_area_map(cam, geo)
    assert area.shape == (cam.intrinsics.height, cam.intrinsics.width)
    f = float(cam.intrinsics.fx)
    us, vs = [640.0, 640.0, 640.0], [330.0, 450.0, 560.0]  # the centre column: no obliquity
    n = 0
    for loc, u, v in zip(geo.geolocate(cam, us, vs), us, vs, strict=True):
        if loc.best is None:
            continue
        r = float(np.linalg.norm(np.asarray(loc.best.p_enu) - np.asarray(cam.position_enu)))
        expected = (f * 0.6 / r) * (f * 1.7 / r)  # a 0.6 m x 1.7 m person, level view
        assert area[int(v), int(u)] == pytest.approx(expected, rel=0.2)
        n += 1
    assert n >= 2
    assert np.isnan(area).any() and np.nanmax(area) > 50 * np.nanmin(area)  # sky; near/far


@pytest.mark.parametrize(
    ("boxes", "partial"),
    [
        ([(10, 0, 40, 9), (10, 0, 36, 9), (10, 0, 32, 9), (10, 0, 28, 9)], True),  # hiding
        ([(50, 0, 52, 9), (46, 0, 52, 9), (42, 0, 52, 9), (38, 0, 52, 9)], True),  # emerging
        ([(10, 0, 40, 9), (6, 0, 36, 9), (2, 0, 32, 9), (-2, 0, 28, 9)], False),  # driving
        ([(10, 0, 40, 9), (10, 0, 40, 9), (10, 0, 40, 9), (10, 0, 40, 9)], False),  # stopped
        ([(10, 0, 40, 9), (10, 0, 41, 9), (10, 0, 40, 9), (10, 0, 42, 9)], False),  # jitter
        ([(10, 0, 40, 9), (10, 0, 36, 9), (10, 0, 32, 9)], False),  # too short
    ],
)
def test_partial_view_is_one_edge_still_the_other_moving_steadily(boxes, partial):
    assert partial_view(boxes) is partial
