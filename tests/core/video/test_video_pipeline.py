"""The video pipeline on the sample site: bodies of a person's and a car's size moving over
the DEM in a camera's view; classified by metric size at the geolocated foot, tracked,
and emitted as Detection records in time order."""

from __future__ import annotations

from collections import Counter

import cv2
import numpy as np
import pytest
from synth import START, Body, iou, match, site_clip

from demtrack.core.errors import VideoError
from demtrack.core.site.folder import load_site
from demtrack.core.video.blobs import Blob
from demtrack.core.video.classify import BlobClassifier, dispersedness
from demtrack.core.video.pipeline import detect_video, site_mask_path, video_detections

PERSON = (0.55, 0.35, 1.75)
CAR = (1.8, 4.5, 1.5)


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


@pytest.fixture(scope="module")
def street(site, tmp_path_factory):
    """A person walking and a car driving in cam1's near field, both appearing at frame 4."""
    bodies = [
        Body("human", (300, 560), (1.4, 0.3), PERSON, grey=40, frames=(4, 10**9)),
        Body("vehicle", (900, 500), (-6.0, 2.0), CAR, grey=200, frames=(4, 10**9)),
    ]
    path = tmp_path_factory.mktemp("street") / "cam1.mp4"
    return site_clip(path, site, "cam1", bodies, n_frames=70)


def test_dispersedness_of_simple_shapes():
    assert dispersedness(4 * 10, 100) == 16.0  # a square
    assert dispersedness(2 * np.pi * 5, np.pi * 25) == pytest.approx(4 * np.pi)
    with pytest.raises(VideoError):
        dispersedness(10, 0)


def test_metric_size_at_the_foot_tells_people_from_cars(site, street):
    cam = site.sensor("cam1").camera
    clf = BlobClassifier(cam, site.geolocator())
    got = Counter()
    for k in range(10, 70, 5):
        for kind, box in street.boxes[k]:
            (c,) = clf.classify([Blob.from_box(box)])
            got[kind, c.cls] += 1
            if kind == "human":  # the box's top is the head: 1.75 m (+ the body's depth)
                assert 1.5 < c.height_m < 2.3 and 0.3 < c.width_m < 1.0
            else:  # side-on it is the car's length
                assert 3.5 < c.width_m < 6.0
    assert got["human", "human"] == 12 and got["vehicle", "vehicle"] == 12


def test_a_small_blob_far_up_is_clutter_not_a_person(site):
    cam = site.sensor("cam1").camera
    clf = BlobClassifier(cam, site.geolocator())
    # a 12 x 32 px box whose foot lies far away is tens of metres tall: no person, no car
    (c,) = clf.classify([Blob.from_box((600.0, 300.0, 612.0, 332.0))])
    assert c.cls == "clutter"


def test_image_only_fallback_uses_aspect_and_dispersedness():
    clf = BlobClassifier()
    tall = Blob((0, 0, 10, 30), 240.0, 80.0, (5, 30))  # dispersedness 26.7
    long = Blob((0, 0, 60, 20), 1100.0, 160.0, (30, 20))
    assert [c.cls for c in clf.classify([tall, long])] == ["human", "vehicle"]


def evaluate(clip, results):
    tp = nt = nf = right = scored = 0
    for res in results:
        truth = clip.boxes[res.index]
        a, b, c = match([t for _, t in truth], [d.bbox for d in res.detections])
        tp, nt, nf = tp + a, nt + b, nf + c
        for d in res.detections:
            best = max(truth, key=lambda t: iou(t[1], d.bbox), default=None)
            if best is not None and iou(best[1], d.bbox) >= 0.5:
                scored += 1
                right += best[0] == d.cls
    return tp / max(nt, 1), tp / max(nf, 1), right / max(scored, 1)


def test_pipeline_recall_precision_and_class_accuracy(site, street):
    pipe = video_detections(site, "cam1", street.path)
    results = list(pipe.results())
    assert [r.index for r in results] == list(range(70))
    recall, precision, accuracy = evaluate(street, results[10:])
    assert recall >= 0.9
    assert precision >= 0.9
    assert accuracy >= 0.95
    dets = [d for r in results for d in r.detections]
    ts = [d.t_s for d in dets]
    assert ts == sorted(ts)
    np.testing.assert_allclose(results[12].t_s, START + 12 / 25, atol=1e-6)
    # one local id per body, each with one class
    ids = Counter((d.local_id, d.cls) for d in dets if d.t_s > START + 0.5)
    assert len({i for i, _ in ids}) == 2 and len(ids) == 2


def test_site_mask_is_found_and_honoured(site, street, tmp_path):
    import shutil

    root = tmp_path / "site"
    shutil.copytree(site.root, root)
    mask = np.zeros((720, 1280), np.uint8)
    mask[450:530, 800:] = 255  # the car's lane
    site_mask_path(root, "cam1").parent.mkdir(exist_ok=True)  # the sample site ships masks/
    cv2.imwrite(str(site_mask_path(root, "cam1")), mask)
    masked = load_site(root)
    dets = list(detect_video(masked, "cam1", street.path))
    assert dets and all(d.cls == "human" for d in dets)


def test_a_video_of_the_wrong_size_is_refused(site, tmp_path):
    from synth import write_video

    clip = write_video(tmp_path / "small.mp4", [], n_frames=3)
    with pytest.raises(VideoError, match="calibrated for 1280x720"):
        video_detections(site, "cam1", clip.path)


def test_apparent_height_of_a_deep_body_seen_from_above():
    from demtrack.core.video.classify import apparent_height_m

    # camera 10 m above the foot, 15 m away; the far top edge (1.5 m up, 4.5 m beyond)
    # lies on the ray through (15 + 4.5, 1.5): at range 15 it is 10 - 8.5 * 15 / 19.5 up
    assert apparent_height_m(1.5, 4.5, 10.0, 15.0) == pytest.approx(10 - 8.5 * 15 / 19.5)
    assert apparent_height_m(1.5, 0.0, 10.0, 15.0) == pytest.approx(1.5)  # no depth
    assert apparent_height_m(1.7, 0.4, 1.0, 30.0) == 1.7  # a camera below the top: level
    # far away the roof's depth hardly shows
    assert apparent_height_m(1.5, 4.5, 10.0, 2000.0) == pytest.approx(1.5, abs=0.02)


def test_the_metric_pipeline_scales_the_minimum_area_with_range(site, street):
    pipe = video_detections(site, "cam1", street.path)
    area = pipe.detector.min_area
    assert isinstance(area, np.ndarray) and area.shape == (720, 1280)
    assert area.min() >= 4.0 and area.max() == 16.0
    # the horizon's far ground (rows 320-360 of the centre column) gets a smaller floor
    # than the near ground at the bottom; the sky above keeps the fixed one
    col = area[:, 640]
    assert col[700] == 16.0 and col[320] < col[360] < 16.0 and col[100] == 16.0
    plain = video_detections(site, "cam1", street.path, metric=False)
    assert plain.detector.min_area == 16.0  # no geometry: the fixed floor
