"""The VSAM detector on synthetic clips: recall and precision at IoU 0.5, ghosts cut by
three-frame differencing (and left by a plain background model), the ignore mask, and
the OpenCV and ONNX components behind the same protocol."""

from __future__ import annotations

import numpy as np
import pytest
from synth import Mover, match, write_video

from demtrack.core.errors import VideoError
from demtrack.core.video.blobs import Blob, blobs_from_mask
from demtrack.core.video.detector import VsamDetector, iou
from demtrack.core.video.opencv_models import KnnDetector, Mog2Detector
from demtrack.core.video.reader import VideoReader

WARMUP = 3


def scores(clip, detector, gray=True, skip=WARMUP):
    tp = nt = nf = 0
    per_frame = []
    for f in VideoReader(clip.path, gray=gray):
        blobs = detector.detect(f)
        per_frame.append(blobs)
        if f.index < skip:
            continue
        a, b, c = match([box for _, box in clip.boxes[f.index]], [bl.bbox for bl in blobs])
        tp, nt, nf = tp + a, nt + b, nf + c
    return tp / max(nt, 1), tp / max(nf, 1), per_frame


@pytest.fixture(scope="module")
def traffic(tmp_path_factory):
    """A person and a car crossing, both entering from outside the frame, drift and noise."""
    path = tmp_path_factory.mktemp("vsam") / "traffic.mp4"
    movers = [
        Mover("human", (-14.0, 90.0), (1.5, 0.2), (12, 36), grey=45),
        Mover("vehicle", (330.0, 170.0), (-3.5, 0.0), (64, 26), grey=205),
    ]
    return write_video(path, movers, n_frames=90, noise=2.5, drift=0.2)


def test_blob_boxes_follow_the_pixel_centre_convention():
    fg = np.zeros((20, 30), np.uint8)
    fg[4:10, 5:8] = 255  # rows 4..9, columns 5..7
    (b,) = blobs_from_mask(fg, min_area_px=1)
    assert b.bbox == (4.5, 3.5, 7.5, 9.5)
    assert b.foot_px == (6.0, 9.5) and b.area_px == 18
    (b2,) = blobs_from_mask(fg, min_area_px=1, scale=2.0)  # a half-size model's blob
    assert b2.bbox == (9.5, 7.5, 15.5, 19.5) and b2.area_px == 72
    assert blobs_from_mask(fg, min_area_px=19) == []


def test_recall_and_precision_at_iou_half(traffic):
    recall, precision, _ = scores(traffic, VsamDetector((320, 240), min_area_px=40))
    assert recall >= 0.9
    assert precision >= 0.9


def test_half_resolution_model_still_finds_them(traffic):
    recall, precision, _ = scores(traffic, VsamDetector((320, 240), min_area_px=40, downscale=2))
    assert recall >= 0.8 and precision >= 0.8


@pytest.fixture(scope="module")
def stop_and_go(tmp_path_factory):
    """A car that stops for 2.4 s (a running average at 0.03 a frame learns 84 %), then goes."""
    path = tmp_path_factory.mktemp("ghost") / "stop.mp4"
    car = Mover("vehicle", (10.0, 100.0), (3.0, 0.0), (60, 24), grey=210, stops=((20, 79),))
    return write_video(path, [car], n_frames=150, noise=2.0, drift=0.0)


def ghost_frames(clip, detector) -> int:
    """Frames after the car left its stop with a box over the empty stop place."""
    place = (10 + 3 * 20 - 0.5, 99.5, 10 + 3 * 20 + 59.5, 123.5)
    n = 0
    for f in VideoReader(clip.path, gray=True):
        blobs = detector.detect(f)
        if f.index < 101:  # the car is clear of its stop place from frame 101 on
            continue
        centres = [((b.bbox[0] + b.bbox[2]) / 2, (b.bbox[1] + b.bbox[3]) / 2) for b in blobs]
        if any(place[0] < u < place[2] and place[1] < v < place[3] for u, v in centres):
            n += 1
    return n


def test_three_frame_differencing_leaves_no_ghost_where_plain_subtraction_does(stop_and_go):
    plain = VsamDetector((320, 240), validate=False, learning_rate=0.03)
    hybrid = VsamDetector((320, 240), learning_rate=0.03)
    assert ghost_frames(stop_and_go, plain) >= 10
    assert ghost_frames(stop_and_go, hybrid) == 0


def test_a_stopped_object_is_still_reported_for_hold_s(stop_and_go):
    det = VsamDetector((320, 240), hold_s=5.0)
    seen = []
    for f in VideoReader(stop_and_go.path, gray=True):
        blobs = det.detect(f)
        if 20 <= f.index <= 79:  # stopped: within 5 s of its last motion
            (true_box,) = [b for _, b in stop_and_go.boxes[f.index]]
            seen.append(any(iou(b.bbox, true_box) >= 0.5 for b in blobs))
    assert all(seen)


@pytest.fixture(scope="module")
def stop_then_leave(tmp_path_factory):
    """A car drives in, stands 4 s (longer than hold_s: it is learnt into the background),
    then leaves downwards, across the image from where it came, as cam2's car does."""
    path = tmp_path_factory.mktemp("ghost2") / "leave.mp4"
    arrive = Mover(
        "vehicle", (-80.0, 60.0), (3.5, 0.0), (80, 50), grey=210, stops=((40, 10**6),),
        hidden=(LEAVE, 10**6),
    )  # fmt: skip
    leave = Mover(
        "vehicle", (60.0, 60.0), (0.0, 1.0), (80, 50), grey=210, stops=((0, LEAVE - 1),),
        hidden=(0, LEAVE - 1),
    )  # fmt: skip
    return write_video(path, [arrive, leave], n_frames=LEAVE + 80, noise=2.0, drift=0.0)


LEAVE = 140  # the frame the car starts to leave its stop place (rows 60..109)


def test_no_box_stays_on_the_place_a_stopped_object_left(stop_then_leave):
    """Once the car has moved off part of its stop place, no box covers that part.

    The place was learnt into the background while the car stood; the empty road that
    reappears there matches the background from before, so it is background at once.
    """
    det = VsamDetector((320, 240), hold_s=2.0)
    late = []
    for f in VideoReader(stop_then_leave.path, gray=True):
        blobs = det.detect(f)
        if f.index < LEAVE + N_GRACE:
            continue
        (car,) = [b for _, b in stop_then_leave.boxes[f.index]]
        if any(b.bbox[1] < car[1] - 3.0 for b in blobs):  # reaches up into the empty place
            late.append(f.index)
    assert late == []


N_GRACE = 5  # frames after the car starts to move in which a box may still cover the place


def test_the_ignore_mask_is_honoured(traffic):
    mask = np.zeros((240, 320), bool)
    mask[150:, :] = True  # the car's lane
    _, _, frames = scores(traffic, VsamDetector((320, 240), min_area_px=40, mask=mask))
    feet = [b.foot_px for blobs in frames for b in blobs]
    assert feet and all(v < 150 for _, v in feet)
    _, _, unmasked = scores(traffic, VsamDetector((320, 240), min_area_px=40))
    assert any(b.foot_px[1] > 150 for blobs in unmasked for b in blobs)


@pytest.mark.parametrize("cls", [Mog2Detector, KnnDetector])
def test_opencv_background_models_share_the_protocol(traffic, cls):
    recall, _, frames = scores(traffic, cls((320, 240), min_area_px=40), gray=False, skip=10)
    assert recall >= 0.7
    assert all(isinstance(b, Blob) for blobs in frames for b in blobs)


def test_bad_parameters_are_refused():
    with pytest.raises(VideoError):
        VsamDetector((320, 240), learning_rate=1.5)
    with pytest.raises(VideoError):
        VsamDetector((4, 4))
    det = VsamDetector((320, 240))
    from demtrack.core.video.reader import Frame

    with pytest.raises(VideoError, match="expects"):
        det.detect(Frame(0, 0.0, np.zeros((100, 100), np.uint8)))
