"""From a video to detections: reader -> detector -> classifier -> blob tracker.

:class:`VideoDetections` reads frames, finds blobs, classifies each by size at its
geolocated foot point and votes the class over the blob's track. Output runs a fixed
``lag`` frames behind the input (``min_history`` of the tracker): a frame's detections
are released once the tracks have that many more frames of history, so each carries the
majority class of its track including its near future, a track too short to commit
(a flicker) never comes out, and records still leave in time order. Clutter is dropped
(and, with ``require_travel``, a track that has not yet travelled in the image), and so
is a blob that is only a part of its object (``whole_only``): its own class this frame
is not its track's, or it is a vehicle's sliding past an occluder's edge
(:func:`~.blob_tracker.partial_view`); its bottom-centre is not the object's foot, and
such feet from two cameras split one car into two tracks downstream.

With a metric classifier and the VSAM detector, the detector's minimum blob area follows
a person's size at the foot pixel (:mod:`.scale`).

Detectors by name (:func:`make_detector`): ``vsam`` (the default,
:class:`~.detector.VsamDetector`), ``mog2``, ``knn`` (OpenCV), ``onnx:PATH`` (a
user-supplied model, :class:`~.onnx_detector.OnnxDetector`).

A camera's ignore mask is ``--mask FILE`` or, stored with the site,
``<site>/masks/<sensor>.png`` (white = ignore, any size: it is resized to the frame).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import VideoError
from ..tracking.types import Detection
from .blob_tracker import BlobTracker, TrackedBlob
from .blobs import MotionDetector, load_mask
from .classify import CLUTTER, BlobClassifier
from .detector import VsamDetector
from .opencv_models import KnnDetector, Mog2Detector
from .reader import Frame, KlvPacket, VideoReader
from .scale import min_area_map, person_area_map

if TYPE_CHECKING:
    from ..site.folder import Site

__all__ = [
    "DETECTORS",
    "FrameResult",
    "VideoDetections",
    "detect_video",
    "make_detector",
    "site_mask_path",
]

#: Detector names :func:`make_detector` knows (plus ``onnx:PATH``).
DETECTORS = ("vsam", "mog2", "knn")


def make_detector(
    spec: str,
    size: tuple[int, int],
    *,
    fps: float = 25.0,
    mask: np.ndarray | None = None,
    **options: Any,
) -> MotionDetector:
    """A detector by name: ``vsam``, ``mog2``, ``knn`` or ``onnx:PATH``."""
    if spec == "vsam":
        return VsamDetector(size, mask=mask, fps=fps, **options)
    if spec == "mog2":
        return Mog2Detector(size, mask=mask, **options)
    if spec == "knn":
        return KnnDetector(size, mask=mask, **options)
    if spec.startswith("onnx:"):
        from .onnx_detector import OnnxDetector

        return OnnxDetector(spec[5:], size, mask=mask, **options)
    raise VideoError(f"unknown detector {spec!r}; choose vsam, mog2, knn or onnx:MODEL.onnx")


def site_mask_path(site_root: str | Path, sensor_id: str) -> Path:
    """Where a site keeps a camera's ignore mask: ``masks/<sensor>.png``."""
    return Path(site_root) / "masks" / f"{sensor_id}.png"


@dataclass(frozen=True)
class FrameResult:
    """One frame's output.

    Its index and time, its detections, the KLV packets read since the previous frame,
    and how many blobs the detector found (clutter included).
    """

    index: int
    t_s: float
    detections: tuple[Detection, ...]
    klv: tuple[KlvPacket, ...] = ()
    n_blobs: int = 0


class VideoDetections:
    """Detections of one camera's video (see the module docstring).

    Parameters
    ----------
    reader : VideoReader
    detector : MotionDetector
    sensor : str
        Sensor id written into each detection.
    classifier : BlobClassifier, optional
        Default: image cues only (no geometry).
    tracker : BlobTracker, optional
    require_travel : bool
        Report a track only once it has travelled (``BlobTrack.moved``); off by default,
        as an object moving along the line of sight hardly travels in the image.
    scale_min_area : bool
        With a metric classifier and the VSAM detector, the detector's minimum blob area
        becomes 40 % of a person's area at each foot pixel (:mod:`.scale`; at least 4 px,
        at most the detector's own minimum), so that far walkers a few pixels wide stay.
    whole_only : bool
        Withhold the blobs that are only a part of their object (module docstring).
    """

    def __init__(
        self,
        reader: VideoReader,
        detector: MotionDetector,
        sensor: str,
        classifier: BlobClassifier | None = None,
        tracker: BlobTracker | None = None,
        *,
        require_travel: bool = False,
        scale_min_area: bool = True,
        whole_only: bool = True,
    ) -> None:
        self.reader = reader
        self.require_travel = bool(require_travel)
        self.whole_only = bool(whole_only)
        self.detector = detector
        self.sensor = sensor
        self.classifier = classifier or BlobClassifier()
        self.tracker = tracker or BlobTracker()
        self.lag = self.tracker.min_history
        if scale_min_area and self.classifier.metric and isinstance(detector, VsamDetector):
            # the minimum blob area follows a person's size at the foot pixel's range
            cam, geo = self.classifier.camera, self.classifier.geolocator
            area = person_area_map(cam, geo)
            if area.shape == detector.size[::-1]:
                detector.set_min_area_map(min_area_map(area, ceil_px=detector.min_area_px))

    def __iter__(self) -> Iterator[Detection]:
        """Every detection, in time order."""
        for result in self.results():
            yield from result.detections

    def _process(self, frame: Frame) -> list[TrackedBlob]:
        blobs = self.detector.detect(frame)
        if not blobs:
            self.tracker.update(frame.t_s, [], [])
            return []
        classes = self.classifier.classify(blobs)
        labels = [b.label or c.cls for b, c in zip(blobs, classes, strict=True)]
        scores = [
            b.score if b.score is not None else c.score for b, c in zip(blobs, classes, strict=True)
        ]
        return self.tracker.update(frame.t_s, blobs, labels, scores)

    def _emit(self, index: int, t_s: float, tracked, klv, tracks) -> FrameResult:
        dets = []
        for tb, track in zip(tracked, tracks, strict=True):
            cls = track.voted_class(self.tracker.min_history)
            if cls is None or cls == CLUTTER or (self.require_travel and not track.moved):
                continue
            if self.whole_only and (tb.frame_cls != cls or (cls == "vehicle" and tb.partial)):
                continue  # a part of the object (hidden, cut): its foot is not the object's
            dets.append(
                Detection(t_s, self.sensor, tb.blob.bbox, cls, round(tb.score, 3), tb.local_id)
            )
        return FrameResult(index, t_s, tuple(dets), tuple(klv), len(tracked))

    def results(self) -> Iterator[FrameResult]:
        """One :class:`FrameResult` per frame, ``lag`` frames behind the decoder."""
        pending: deque = deque()
        klv: list[KlvPacket] = []
        for item in self.reader.items():
            if isinstance(item, KlvPacket):
                klv.append(item)
                continue
            tracked = self._process(item)
            by_id = {tr.local_id: tr for tr in self.tracker.tracks}
            tracks = [by_id[tb.local_id] for tb in tracked]
            pending.append((item.index, item.t_s, tracked, klv, tracks))
            klv = []
            if len(pending) > self.lag:
                yield self._emit(*pending.popleft())
        while pending:
            yield self._emit(*pending.popleft())
        if klv:
            yield FrameResult(-1, float("nan"), (), tuple(klv))


def detect_video(
    site: Site,
    sensor_id: str,
    source: str | Path,
    *,
    detector: str = "vsam",
    start_utc_s: float | None = None,
    mask: str | Path | np.ndarray | None = None,
    latency_s: float = 0.0,
    metric: bool = True,
) -> Iterator[Detection]:
    """Detections of ``sensor_id``'s video ``source`` on ``site`` (see :func:`video_detections`)."""
    return iter(
        video_detections(
            site,
            sensor_id,
            source,
            detector=detector,
            start_utc_s=start_utc_s,
            mask=mask,
            latency_s=latency_s,
            metric=metric,
        )
    )


def video_detections(
    site: Site,
    sensor_id: str,
    source: str | Path,
    *,
    detector: str = "vsam",
    start_utc_s: float | None = None,
    mask: str | Path | np.ndarray | None = None,
    latency_s: float = 0.0,
    metric: bool = True,
    threads: int = 0,
    timeout_s: float = 5.0,
) -> VideoDetections:
    """The assembled pipeline for one camera of a site.

    ``mask`` is a PNG path or a boolean array (True = ignore); None looks for the site's
    ``masks/<sensor>.png``. ``timeout_s``: a live stream's open and read timeout.
    ``metric`` classifies by size in metres (the camera and the
    site's DEM); False by image cues alone.

    Raises
    ------
    UnknownSensorError
        The site has no such sensor.
    VideoError
        The video cannot be read, needs ``--start``, or its frame size is not the camera's.
    """
    sensor = site.sensor(sensor_id)
    gray = not detector.startswith(("onnx:", "mog2", "knn"))
    reader = VideoReader(
        source,
        start_utc_s=start_utc_s,
        gray=gray,
        latency_s=latency_s,
        threads=threads,
        timeout_s=timeout_s,
    )
    cam = sensor.camera
    w, h = cam.intrinsics.width, cam.intrinsics.height
    if reader.size != (w, h):
        raise VideoError(
            f"video {source} is {reader.size[0]}x{reader.size[1]} but camera {sensor_id} "
            f"is calibrated for {w}x{h}"
        )
    if mask is None and site_mask_path(site.root, sensor_id).is_file():
        mask = site_mask_path(site.root, sensor_id)
    mask_arr = load_mask(str(mask), reader.size) if isinstance(mask, str | Path) else mask
    det = make_detector(detector, reader.size, fps=reader.fps, mask=mask_arr)
    classifier = BlobClassifier(cam, site.geolocator()) if metric else BlobClassifier()
    return VideoDetections(reader, det, sensor_id, classifier)
