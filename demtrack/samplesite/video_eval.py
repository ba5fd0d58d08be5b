"""Score a video detector against a sample video's true boxes.

Per frame, detections are matched to the counted true boxes (:mod:`.video_render`) by
the Hungarian algorithm on IoU, pairs below :data:`MIN_IOU` rejected. A matched pair is
a true positive; an unmatched counted box a miss; an unmatched detection a false alarm,
unless at least half of it lies on a box that is in view but not counted (mostly hidden
or cut by the border): that one is neither (an "ignore region", as MOT benchmarks do).
A detection whose time is more than half a frame from every frame counts as false.
Frames before ``score_from_s`` (default: the scenario's first motion, after the video's
lead-in, which is the detector's time to learn the scene) are not scored at all, as the
change-detection benchmarks leave out their first frames (CDnet's temporal ROI).

The foot pixel is a box's bottom centre (the paper's); its error on the ground is the
horizontal distance between the site geolocator's first hits of the detected and the
true foot pixels (the calibrated cameras, as the tracker sees them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from demtrack.core.geolocation.geolocate import Geolocator
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Detection

from .video_file import VideoTruth

__all__ = [
    "MIN_IOU",
    "DetectionScores",
    "iou_matrix",
    "match_boxes",
    "score_detections",
    "scored_from",
    "truth_detections",
]

MIN_IOU = 0.5
#: Box heights (px) binning the recall: far walkers are under 10 px tall here.
SIZE_EDGES_PX = (10.0, 20.0)


@dataclass(frozen=True)
class DetectionScores:
    """Detection quality of one sensor's video (or several pooled).

    Parameters
    ----------
    sensor : str
    n_truth, n_detections : int
        Counted true boxes; detections (ignored ones excluded).
    true_positives : int
    ious : ndarray
        IoU of each matched pair.
    class_correct : int
        Matched pairs whose class is the true one.
    foot_px, foot_m : ndarray
        Foot-pixel error of each matched pair (px), and on the ground (m; NaN where a
        foot pixel's ray meets no ground).
    n_ignored : int
        Detections on boxes that are not counted.
    truth_heights_px, truth_found : ndarray
        Height (px) of each counted true box, and whether it was matched (recall by size).
    """

    sensor: str
    n_truth: int
    n_detections: int
    true_positives: int
    ious: np.ndarray = field(repr=False)
    class_correct: int
    foot_px: np.ndarray = field(repr=False)
    foot_m: np.ndarray = field(repr=False)
    n_ignored: int = 0
    truth_heights_px: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    truth_found: np.ndarray = field(default_factory=lambda: np.zeros(0, bool), repr=False)

    def recall_by_height(self, edges_px: Sequence[float] = SIZE_EDGES_PX) -> dict[str, float]:
        """Recall of the true boxes binned by their height (px): ``"lo-hi px"`` -> recall."""
        out = {}
        bounds = [0.0, *edges_px, math.inf]
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            sel = (self.truth_heights_px >= lo) & (self.truth_heights_px < hi)
            name = f"{lo:g}-{hi:g} px" if math.isfinite(hi) else f">= {lo:g} px"
            if sel.any():
                out[name] = round(float(self.truth_found[sel].mean()), 4)
        return out

    @property
    def precision(self) -> float:
        """True positives over detections (1 with no detections)."""
        return self.true_positives / self.n_detections if self.n_detections else 1.0

    @property
    def recall(self) -> float:
        """True positives over counted true boxes (1 with none)."""
        return self.true_positives / self.n_truth if self.n_truth else 1.0

    @property
    def mean_iou(self) -> float:
        """Mean IoU of the matched pairs (NaN with none)."""
        return float(self.ious.mean()) if len(self.ious) else float("nan")

    @property
    def class_accuracy(self) -> float:
        """Share of matched pairs with the right class (NaN with none)."""
        return self.class_correct / self.true_positives if self.true_positives else float("nan")

    def summary(self) -> dict[str, float | int | str]:
        """The figures as plain numbers (JSON-ready)."""
        fm = self.foot_m[np.isfinite(self.foot_m)]

        def q(a: np.ndarray, p: float) -> float:
            return round(float(np.percentile(a, p)), 3) if len(a) else float("nan")

        return {
            "sensor": self.sensor,
            "truth_boxes": self.n_truth,
            "detections": self.n_detections,
            "true_positives": self.true_positives,
            "ignored": self.n_ignored,
            "precision": round(self.precision, 4),
            "recall": round(self.recall, 4),
            "mean_iou": round(self.mean_iou, 4),
            "class_accuracy": round(self.class_accuracy, 4),
            "foot_px_median": q(self.foot_px, 50),
            "foot_px_p95": q(self.foot_px, 95),
            "foot_m_median": q(fm, 50),
            "foot_m_p95": q(fm, 95),
            "recall_by_height": self.recall_by_height(),
        }

    @staticmethod
    def pooled(scores: Sequence[DetectionScores], name: str = "all") -> DetectionScores:
        """Several sensors' scores as one."""
        return DetectionScores(
            name,
            sum(s.n_truth for s in scores),
            sum(s.n_detections for s in scores),
            sum(s.true_positives for s in scores),
            np.concatenate([s.ious for s in scores]) if scores else np.zeros(0),
            sum(s.class_correct for s in scores),
            np.concatenate([s.foot_px for s in scores]) if scores else np.zeros(0),
            np.concatenate([s.foot_m for s in scores]) if scores else np.zeros(0),
            sum(s.n_ignored for s in scores),
            np.concatenate([s.truth_heights_px for s in scores]) if scores else np.zeros(0),
            np.concatenate([s.truth_found for s in scores]) if scores else np.zeros(0, bool),
        )


def iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of every box of ``a`` (n, 4) with every box of ``b`` (m, 4): shape (n, m)."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    iw = np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0])
    ih = np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.clip(iw, 0, None) * np.clip(ih, 0, None)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(union > 0, inter / union, 0.0)


def _ioa(det: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Share of the detection's area inside each box, shape (m,)."""
    iw = np.minimum(det[2], boxes[:, 2]) - np.maximum(det[0], boxes[:, 0])
    ih = np.minimum(det[3], boxes[:, 3]) - np.maximum(det[1], boxes[:, 1])
    area = max((det[2] - det[0]) * (det[3] - det[1]), 1e-9)
    return np.clip(iw, 0, None) * np.clip(ih, 0, None) / area


def match_boxes(
    dets: np.ndarray, truths: np.ndarray, min_iou: float = MIN_IOU
) -> list[tuple[int, int, float]]:
    """Optimal one-to-one matching on IoU: ``(det index, truth index, IoU)`` pairs."""
    if not len(dets) or not len(truths):
        return []
    iou = iou_matrix(dets, truths)
    rows, cols = linear_sum_assignment(-iou)
    return [
        (int(i), int(j), float(iou[i, j]))
        for i, j in zip(rows, cols, strict=True)
        if iou[i, j] >= min_iou
    ]


def _foot(box: Sequence[float]) -> tuple[float, float]:
    return (box[0] + box[2]) / 2.0, box[3]


def scored_from(truth: VideoTruth, score_from_s: float | None = None) -> float:
    """UNIX time of the first scored frame.

    ``score_from_s`` scenario seconds; by default the scenario's first motion (``-inf``
    for a truth file without it).
    """
    if score_from_s is None:
        score_from_s = truth.header.get("t_first_motion_s", -math.inf)
    return truth.start_s + float(score_from_s) - 1e-6


def score_detections(
    site: Site,
    detections: Sequence[Detection],
    truth: VideoTruth,
    min_iou: float = MIN_IOU,
    score_from_s: float | None = None,
) -> DetectionScores:
    """Score one sensor's detections against its video's true boxes (module docstring).

    ``score_from_s`` : scenario seconds of the first scored frame (:func:`scored_from`).
    """
    sensor = truth.sensor
    t_scored = scored_from(truth, score_from_s)
    frames = [f for f in truth.frames if f["t_s"] >= t_scored]
    detections = [d for d in detections if d.t_s >= t_scored - 0.5 / truth.header["rate_hz"]]
    t_frames = np.array([f["t_s"] for f in frames], dtype=np.float64)
    half = 0.5 / float(truth.header["rate_hz"])
    per_frame: dict[int, list[Detection]] = {}
    n_det = n_ignored = 0
    heights: list[float] = []
    found: list[bool] = []
    for d in detections:
        if d.sensor != sensor:
            continue
        k = int(np.argmin(np.abs(t_frames - d.t_s))) if len(t_frames) else -1
        if k < 0 or abs(t_frames[k] - d.t_s) > half:
            n_det += 1  # at no frame's time: false
            continue
        per_frame.setdefault(k, []).append(d)
    n_truth = tp = correct = 0
    ious: list[float] = []
    feet: list[tuple[tuple[float, float], tuple[float, float]]] = []
    for k, frame in enumerate(frames):
        counted = [t for t in frame["targets"] if t["counted"]]
        ignore = np.array([t["bbox"] for t in frame["targets"] if t["bbox"] and not t["counted"]])
        n_truth += len(counted)
        heights += [t["bbox"][3] - t["bbox"][1] for t in counted]
        dets = per_frame.get(k, [])
        d_boxes = np.array([d.bbox for d in dets], dtype=np.float64).reshape(-1, 4)
        t_boxes = np.array([t["bbox"] for t in counted], dtype=np.float64).reshape(-1, 4)
        pairs = match_boxes(d_boxes, t_boxes, min_iou)
        matched = {i for i, _, _ in pairs}
        hit = {j for _, j, _ in pairs}
        found += [j in hit for j in range(len(counted))]
        for i, j, iou in pairs:
            tp += 1
            ious.append(iou)
            correct += dets[i].cls == counted[j]["class"]
            feet.append((_foot(dets[i].bbox), _foot(counted[j]["bbox"])))
        for i in range(len(dets)):
            if i in matched:
                continue
            if len(ignore) and _ioa(d_boxes[i], ignore).max() >= 0.5:
                n_ignored += 1
            else:
                n_det += 1
        n_det += len(matched)
    foot_px = np.array([np.hypot(a[0] - b[0], a[1] - b[1]) for a, b in feet])
    foot_m = _ground_errors(site, sensor, feet)
    return DetectionScores(
        sensor,
        n_truth,
        n_det,
        tp,
        np.array(ious),
        correct,
        foot_px,
        foot_m,
        n_ignored,
        np.array(heights),
        np.array(found, dtype=bool),
    )


def _ground_errors(
    site: Site, sensor: str, feet: list[tuple[tuple[float, float], tuple[float, float]]]
) -> np.ndarray:
    """Horizontal distance (m) between the ground points of detected and true feet."""
    if not feet:
        return np.zeros(0)
    camera = site.sensors[sensor].camera
    w, h = camera.intrinsics.width, camera.intrinsics.height
    pts = np.array([[*a, *b] for a, b in feet], dtype=np.float64)
    u = np.clip(np.concatenate([pts[:, 0], pts[:, 2]]), -0.5, w - 0.5)
    v = np.clip(np.concatenate([pts[:, 1], pts[:, 3]]), -0.5, h - 0.5)
    geo = Geolocator(site.dem, site.frame)
    locs = geo.geolocate(camera, u, v, rule="first")
    xy = np.array(
        [loc.best.p_enu[:2] if loc.best is not None else (np.nan, np.nan) for loc in locs]
    )
    n = len(feet)
    return np.hypot(*(xy[:n] - xy[n:]).T)


def truth_detections(truth: VideoTruth) -> list[Detection]:
    """The counted true boxes as detections (exact boxes, true classes, score 1)."""
    out = []
    for frame in truth.frames:
        for t in frame["targets"]:
            if t["counted"]:
                out.append(
                    Detection(float(frame["t_s"]), truth.sensor, tuple(t["bbox"]), t["class"], 1.0)
                )  # type: ignore[arg-type]
    return out
