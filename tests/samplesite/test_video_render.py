"""The sample video's renderer: box geometry, pixels against truth, occlusion, clutter."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from demtrack.core.raycast.cast import RayCaster
from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import (
    SCENARIOS,
    image_boxes,
    site_world,
    target_points,
    true_cameras,
)
from demtrack.samplesite.video_render import FrameRenderer, RenderLook, frame_times
from demtrack.samplesite.video_scene import BoxPose, box_corners, box_hits, camera_scene

CLEAN = RenderLook(noise_sigma=0.0, drift=0.0, sway=0.0)


@pytest.fixture(scope="module")
def cam1(sample_site_dir):
    """The sample site, its world, the vehicle run and cam1's static scene."""
    site = load_site(sample_site_dir)
    world = site_world(site)
    camera = true_cameras(site)["cam1"]
    return site, world, SCENARIOS["vehicle-run"](world), camera_scene(site, world, camera)


def _inside(pose: BoxPose, p: np.ndarray) -> np.ndarray:
    a, c0 = pose.affine()
    q = (p - c0) @ a.T
    return (
        (np.abs(q[..., 0]) <= 0.5)
        & (np.abs(q[..., 1]) <= 0.5)
        & (q[..., 2] >= 0)
        & (q[..., 2] <= 1)
    )


def test_box_hits_analytic_and_against_a_ray_march():
    pose = BoxPose((10.0, 5.0), (0.6, 0.8), (4.5, 1.8, 1.5), 2.0, (0.05, -0.02))
    # Straight down onto the centre of the top: the top lies 1.5 m above the plane there.
    r, n, hgt = box_hits(pose, np.array([10.0, 5.0, 20.0]), np.array([[0.0, 0.0, -1.0]]))
    assert r[0] == pytest.approx(20.0 - 3.5, abs=1e-9)
    expected = np.array([-0.05, 0.02, 1.0]) / np.linalg.norm([-0.05, 0.02, 1.0])
    np.testing.assert_allclose(n[0], expected, atol=1e-12)
    assert hgt[0] == pytest.approx(1.0)
    # Random rays from a camera: the first inside point of a fine march is the hit.
    rng = np.random.default_rng(0)
    origin = np.array([-20.0, -15.0, 12.0])
    target = box_corners(pose).mean(axis=0) + rng.normal(0, 1.5, (300, 3))
    d = target - origin
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r, _, _ = box_hits(pose, origin, d)
    steps = np.arange(0, 60, 0.002)
    inside = _inside(pose, origin + steps[None, :, None] * d[:, None, :])
    first = np.where(inside.any(axis=1), steps[np.argmax(inside, axis=1)], np.inf)
    assert np.isfinite(r).sum() > 50 and (~np.isfinite(r)).sum() > 20  # both kinds tried
    # The march may step over a grazing chord (under 2 mm): there, just past the hit
    # must be inside the box.
    grazing = np.isfinite(r) & ~np.isfinite(first)
    assert grazing.sum() <= 3
    assert _inside(pose, origin + (r[grazing] + 1e-7)[:, None] * d[grazing]).all()
    assert not (np.isfinite(first) & ~np.isfinite(r)).any()
    hit = np.isfinite(r) & np.isfinite(first)
    np.testing.assert_allclose(r[hit], first[hit], atol=0.003)


def test_frame_times():
    t = frame_times(-5.0, 1.0, 10.0)
    assert len(t) == 61 and t[0] == -5.0 and t[-1] == pytest.approx(1.0)
    assert len(frame_times(0.0, 0.0, 10.0)) == 1


def test_truth_boxes_agree_with_the_scenarios_sample_points(cam1):
    """Two independent visibilities: per-pixel depth test against points cast at the DEM."""
    site, world, targets, scene = cam1
    renderer = FrameRenderer(scene, world, targets, look=CLEAN)
    caster = RayCaster.from_dem(site.dem)
    tg = targets[0]
    full = partial = 0
    for t in np.arange(5.0, 100.0, 2.5):
        _, truth = renderer.render(float(t))
        xy, head = tg.motion.pose(np.array([t]))
        boxes, fraction, _ = image_boxes(
            scene.camera, caster, target_points(xy, head, tg.size_m, world)
        )
        if not truth or truth[0].bbox is None or not np.isfinite(boxes[0, 0]):
            assert not truth or not truth[0].counted or fraction[0] < 0.35
            continue
        tt = truth[0]
        if tt.visible_fraction == 1.0 and fraction[0] == 1.0:
            full += 1
            np.testing.assert_allclose(tt.bbox, boxes[0], atol=1.0)
        else:
            partial += 1
            assert abs(tt.visible_fraction - fraction[0]) < 0.2
    assert full >= 15 and partial >= 2


def test_pixels_drawn_are_the_truth_box(cam1):
    """Without noise, drift and sway a frame is the still plus the target's pixels."""
    _, world, targets, scene = cam1
    renderer = FrameRenderer(scene, world, targets, look=CLEAN)
    still = np.clip(scene.background + 0.5, 0, 255).astype(np.uint8)
    empty, truth = renderer.render(-2.0)
    assert truth == []
    np.testing.assert_array_equal(empty, still)
    image, truth = renderer.render(10.0)
    changed = np.nonzero((image != still).any(axis=2))
    (tt,) = truth
    assert tt.counted and tt.visible_fraction == 1.0
    box = (
        changed[1].min() - 0.5,
        changed[0].min() - 0.5,
        changed[1].max() + 0.5,
        changed[0].max() + 0.5,
    )
    assert box == tt.bbox


def test_occlusion_by_the_dem_hides_pixels_and_lowers_the_fraction(cam1):
    """A partly hidden car: the same render with the DEM made transparent shows more."""
    _, world, targets, scene = cam1
    clear = replace(scene, range_m=np.full(scene.shape, np.inf))
    still = np.clip(scene.background + 0.5, 0, 255).astype(np.uint8)
    found = False
    for t in np.arange(45.0, 95.0, 0.5):
        image, truth = FrameRenderer(scene, world, targets, look=CLEAN).render(float(t))
        if not truth or not 0.3 < truth[0].visible_fraction < 0.95:
            continue
        seen, truth_clear = FrameRenderer(clear, world, targets, look=CLEAN).render(float(t))
        n_drawn = int((image != still).any(axis=2).sum())
        n_all = int((seen != still).any(axis=2).sum())
        assert truth_clear[0].visible_fraction == 1.0
        # A drawn pixel may match the still by chance; a few in a thousand at most.
        assert truth[0].visible_fraction == pytest.approx(n_drawn / n_all, abs=0.01)
        found = True
        break
    assert found, "no partly hidden frame in the vehicle run"


def test_crowns_sway_and_nothing_else_moves(cam1):
    _, world, targets, scene = cam1
    look = RenderLook(noise_sigma=0.0, drift=0.0, sway=1.0)
    renderer = FrameRenderer(scene, world, targets, seed=3, look=look)
    a, _ = renderer.render(-4.0)
    b, _ = renderer.render(-3.3)
    moved = (np.abs(a.astype(int) - b.astype(int)) > 0).any(axis=2)
    region = np.zeros(scene.shape, dtype=bool)
    region[scene.sway_rows, scene.sway_cols] = True
    assert moved.sum() > 500
    assert not (moved & ~region).any()


def test_noise_and_drift(cam1):
    _, world, targets, scene = cam1
    look = RenderLook(noise_sigma=2.0, drift=0.05, sway=0.0)
    renderer = FrameRenderer(scene, world, targets, seed=1, look=look)
    gains = [renderer.gain(t) for t in np.arange(0, 200, 0.5)]
    assert 0.95 <= min(gains) < 0.98 and 1.02 < max(gains) <= 1.05
    image, _ = renderer.render(-4.0)
    residual = image.astype(float) - np.clip(scene.background * renderer.gain(-4.0), 0, 255)
    unclipped = (scene.background > 10).all(axis=2) & (scene.background < 240).all(axis=2)
    assert np.std(residual[unclipped]) == pytest.approx(np.hypot(2.0, 1 / np.sqrt(12)), rel=0.05)
