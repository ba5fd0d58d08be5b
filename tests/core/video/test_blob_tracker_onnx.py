"""The blob tracker (ids through a short occlusion, the class vote) and the ONNX detector
adapter with a tiny model the test builds itself."""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper

from demtrack.core.errors import VideoError
from demtrack.core.video.blob_tracker import BlobTracker
from demtrack.core.video.blobs import Blob
from demtrack.core.video.onnx_detector import OnnxDetector
from demtrack.core.video.reader import Frame


def box_at(u: float, v: float, w: float = 12, h: float = 30) -> Blob:
    return Blob.from_box((u, v, u + w, v + h))


def test_ids_survive_a_short_occlusion_and_two_crossing_walkers_keep_theirs():
    tr = BlobTracker(max_missed_s=1.0, min_history=3)
    ids_a, ids_b = [], []
    for k in range(60):
        t = k * 0.04
        blobs, which = [], []
        if not 20 <= k < 35:  # a is hidden behind a tree for 0.6 s
            blobs.append(box_at(20 + 3 * k, 100))
            which.append("a")
        blobs.append(box_at(300 - 2 * k, 160))
        which.append("b")
        out = tr.update(t, blobs, ["human"] * len(blobs))
        for w, o in zip(which, out, strict=True):
            (ids_a if w == "a" else ids_b).append(o.local_id)
    assert len(set(ids_a)) == 1 and len(set(ids_b)) == 1 and ids_a[0] != ids_b[0]


def test_a_track_lost_for_longer_than_max_missed_gets_a_new_id():
    tr = BlobTracker(max_missed_s=0.2)
    first = tr.update(0.0, [box_at(0, 0)], ["human"])[0].local_id
    again = tr.update(1.0, [box_at(0, 0)], ["human"])[0].local_id
    assert first != again


def test_the_class_is_the_majority_so_far_after_min_history():
    tr = BlobTracker(min_history=4)
    labels = ["vehicle", "human", "vehicle", "vehicle", "human", "human", "human", "human"]
    voted = [tr.update(k * 0.04, [box_at(10 + k, 50)], [c])[0].cls for k, c in enumerate(labels)]
    assert voted[:3] == [None, None, None]
    assert voted[3] == "vehicle"  # 3 of 4
    assert voted[-1] == "human"  # 5 of 8 by the end
    with pytest.raises(VideoError):
        tr.update(1.0, [box_at(0, 0)], [])


def region_model(path, x0: int, y0: int, x1: int, y1: int, threshold: float = 0.5) -> None:
    """An ONNX graph: the mean of the image's region [y0:y1, x0:x1]; above ``threshold`` it
    reports one human box over the region (score = the mean), else a box with score 0."""
    node = helper.make_node
    consts = {
        "starts": np.array([y0, x0], np.int64),
        "ends": np.array([y1, x1], np.int64),
        "axes": np.array([2, 3], np.int64),
        "box": np.array([[x0 - 0.5, y0 - 0.5, x1 - 0.5, y1 - 0.5]], np.float32),
        "thr": np.array(threshold, np.float32),
        "cls": np.array([0], np.int64),
        "shape1": np.array([1], np.int64),
    }
    inits = []
    for k, v in consts.items():
        kind = TensorProto.FLOAT if v.dtype == np.float32 else TensorProto.INT64
        inits.append(helper.make_tensor(k, kind, v.shape, v.ravel().tolist()))
    nodes = [
        node("Slice", ["image", "starts", "ends", "axes"], ["patch"]),
        node("ReduceMean", ["patch"], ["mean"], keepdims=0),
        node("Greater", ["mean", "thr"], ["hit"]),
        node("Cast", ["hit"], ["hitf"], to=TensorProto.FLOAT),
        node("Mul", ["mean", "hitf"], ["score0"]),
        node("Reshape", ["score0", "shape1"], ["scores"]),
        node("Identity", ["box"], ["boxes"]),
        node("Identity", ["cls"], ["classes"]),
    ]
    graph = helper.make_graph(
        nodes,
        "region",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, "h", "w"])],
        [
            helper.make_tensor_value_info("boxes", TensorProto.FLOAT, [1, 4]),
            helper.make_tensor_value_info("scores", TensorProto.FLOAT, [1]),
            helper.make_tensor_value_info("classes", TensorProto.INT64, [1]),
        ],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def test_onnx_detector_reports_the_models_box(tmp_path):
    path = tmp_path / "region.onnx"
    region_model(path, 40, 20, 60, 70)
    det = OnnxDetector(path, (160, 120), min_score=0.3)
    dark = np.zeros((120, 160, 3), np.uint8)
    assert det.detect(Frame(0, 0.0, dark)) == []
    bright = dark.copy()
    bright[20:70, 40:60] = 230
    (b,) = det.detect(Frame(1, 0.04, bright))
    assert b.bbox == (39.5, 19.5, 59.5, 69.5)
    assert b.label == "human" and b.score == pytest.approx(230 / 255, abs=1e-5)
    assert b.foot_px == (49.5, 69.5)
    masked = OnnxDetector(path, (160, 120), min_score=0.3, mask=np.ones((120, 160), bool))
    assert masked.detect(Frame(1, 0.04, bright)) == []


def test_onnx_detector_refuses_what_it_cannot_use(tmp_path):
    with pytest.raises(VideoError, match="not found"):
        OnnxDetector(tmp_path / "none.onnx", (160, 120))
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(VideoError, match="cannot load"):
        OnnxDetector(junk, (160, 120))
    path = tmp_path / "region.onnx"
    region_model(path, 0, 0, 10, 10)
    det = OnnxDetector(path, (160, 120))
    with pytest.raises(VideoError, match="RGB"):
        det.detect(Frame(0, 0.0, np.zeros((120, 160), np.uint8)))
