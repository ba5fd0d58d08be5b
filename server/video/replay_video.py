"""The live replay from video: each camera's video decoded and detected in the replay's clock.

Instead of the scenario's boxes, the detections come from the video detector
(:mod:`demtrack.core.video`: VSAM background subtraction, the blob classifier by size in
metres, the per-camera blob tracker) run on each camera's video of the scenario
(:class:`~.source.VideoClip`, from a :class:`~.source.VideoScenarioSource`).

One thread per camera decodes (one decoder thread) and detects every frame, running
ahead of the replay clock by at most a bounded queue (:data:`LEAD_FRAMES` frames); it
JPEG-encodes only the frames the panel will show, at most ``frame_hz`` per wall second
(at 1x and 10 Hz video: every other frame at the default 5; at 4x one frame in eight), so
higher speeds skip frames for the panel but never for detection. One player thread
merges the cameras' frames in time order and paces them at ``speed`` x real time: when
frames fall due it ingests their detections as one batch (``Pipeline.ingest``) and then
puts each camera's newest encoded frame, with its boxes, into the frame book - so the
frame and its boxes reach the console together.

The scenarios play one after another (a camera shows one video at a time), each from its
clips' first frame to their last, ``gap_s`` apart, looping. A scenario's time ``tau`` in
loop ``k`` plays at ``t0_s + k * period + offset + (tau - t_from)``; local ids of each
clip are offset (``clip * 100000``) so a later loop never continues an earlier one's
blob track. A clip's frames before its ``detect_from_s`` (the sample videos' lead-in, the
detector learning the scene) are shown but their detections are not sent. When decoding
and detecting cannot keep up, the player waits for the frames (its lateness is
:attr:`VideoReplay.late_s`) and then moves its clock on, so the replay slows rather than
bursts.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from demtrack.core.errors import VideoError
from demtrack.core.site.folder import Site
from demtrack.core.video.blobs import load_mask
from demtrack.core.video.classify import BlobClassifier
from demtrack.core.video.pipeline import VideoDetections, make_detector, site_mask_path
from demtrack.core.video.reader import Frame, VideoReader

from .frame_book import FrameBook
from .frame_keeper import FrameKeeper
from .jpeg import encode_jpeg
from .source import VideoClip

__all__ = ["LEAD_FRAMES", "VideoItem", "VideoReplay", "playlist"]

log = logging.getLogger("demtrack.server")

#: Frames a camera thread may decode ahead of the replay clock.
LEAD_FRAMES = 40
#: Local ids of clip ``k`` (in play order, loops counted) start at ``k * LOCAL_ID_STRIDE``.
LOCAL_ID_STRIDE = 100_000


@dataclass(frozen=True)
class VideoItem:
    """One camera frame on the replay clock: its detections and, if shown, its JPEG."""

    t_s: float
    sensor: str
    records: tuple[dict[str, Any], ...]
    jpeg: bytes | None


def playlist(spans: Sequence[tuple[float, float]], gap_s: float) -> tuple[list[float], float]:
    """Each scenario's offset in a loop and the loop's period (replay seconds).

    ``spans`` are the scenarios' ``(t_from_s, t_to_s)`` in play order; scenario ``j``
    starts ``offsets[j]`` after the loop starts, the next one ``gap_s`` after it ends.
    """
    offsets, at = [], 0.0
    for t_from, t_to in spans:
        offsets.append(at)
        at += max(t_to - t_from, 0.0) + gap_s
    return offsets, at


class VideoReplay:
    """Plays scenarios from video into the pipeline and the frame book (see the module).

    Parameters
    ----------
    site : Site
    clips : callable
        Returns, per scenario in play order, sensor id -> :class:`~.source.VideoClip`.
        Called in the replay's thread (rendering videos may take minutes), then
        ``after`` (optional), then the cameras start.
    ingest : callable
        ``ingest(records)``: one batch of detection records (``Pipeline.ingest``).
    book : FrameBook
    t0_s : float
        Replay time of the first scenario's first frame (UNIX s).
    speed : float
        Replay seconds per wall second.
    frame_hz : float
        Most frames per wall second per camera into the book.
    loop : bool
    gap_s : float
        Replay seconds between two scenarios (and loops).
    duration_s : float, optional
        Stop after this much replay time.
    detector : str
        :func:`~demtrack.core.video.pipeline.make_detector` name.
    max_lag_s : float
        The player moves its clock on when it is this late (wall seconds).
    clock : callable
        Monotonic wall clock (s).
    """

    def __init__(
        self,
        site: Site,
        clips: Callable[[], Sequence[dict[str, VideoClip]]],
        ingest: Callable[[list[dict[str, Any]]], Any],
        book: FrameBook,
        *,
        t0_s: float,
        speed: float = 1.0,
        frame_hz: float = 5.0,
        loop: bool = True,
        gap_s: float = 5.0,
        duration_s: float | None = None,
        detector: str = "vsam",
        max_lag_s: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
        after: Callable[[], Any] | None = None,
    ) -> None:
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"replay speed must be a positive number, got {speed}")
        self.site, self.make_clips, self.ingest, self.book = site, clips, ingest, book
        self.t0_s, self.speed, self.frame_hz = float(t0_s), float(speed), float(frame_hz)
        self.loop, self.gap_s, self.duration_s = loop, float(gap_s), duration_s
        self.detector, self.max_lag_s, self.clock = detector, float(max_lag_s), clock
        self.after = after
        self.clips: list[dict[str, VideoClip]] = []
        self.sensors: list[str] = []
        self.spans: list[tuple[float, float]] = []
        self.offsets: list[float] = []
        self.period_s = 0.0
        self._queues: dict[str, queue.Queue] = {}
        self.n_frames: dict[str, int] = {}
        self.busy_s: dict[str, float] = {}  # wall s decoding, detecting, encoding
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.error: BaseException | None = None
        self.n_detections = 0
        self.n_batches = 0
        self.n_shown = 0
        self.late_s = 0.0  # the player's greatest lateness (wall s) before moving on
        self.n_clock_moves = 0
        self.t_s: float | None = None

    # -------------------------------------------------------------- lifecycle
    @property
    def running(self) -> bool:
        """Whether the player thread is alive."""
        return bool(self._threads) and self._threads[0].is_alive()

    def start(self) -> VideoReplay:
        """Start the replay thread: it makes the clips, starts the cameras, then plays."""
        if self._threads:
            raise RuntimeError("video replay already started")
        thread = threading.Thread(
            target=self._guard, args=(self._main,), name="demtrack-video-replay", daemon=True
        )
        self._threads.append(thread)
        thread.start()
        return self

    def _main(self) -> None:
        self.clips = [dict(c) for c in self.make_clips()]
        self.sensors = sorted({s for c in self.clips for s in c})
        self.spans = [
            (min(c.t_from_s for c in cl.values()), max(c.t_to_s for c in cl.values()))
            for cl in self.clips
            if cl
        ]
        self.clips = [cl for cl in self.clips if cl]
        self.offsets, self.period_s = playlist(self.spans, self.gap_s)
        self._queues = {s: queue.Queue(maxsize=LEAD_FRAMES) for s in self.sensors}
        self.n_frames = {s: 0 for s in self.sensors}
        self.busy_s = {s: 0.0 for s in self.sensors}
        if self.after is not None:
            self.after()
        if self._stop.is_set() or not self.sensors:
            return
        for s in self.sensors:
            thread = threading.Thread(
                target=self._guard, args=(self._camera, s), name=f"demtrack-video-{s}", daemon=True
            )
            self._threads.append(thread)
            thread.start()
        self._play()

    def stop(self, timeout_s: float = 10.0) -> bool:
        """Stop every thread; True once they ended."""
        self._stop.set()
        deadline = time.monotonic() + timeout_s
        for t in list(self._threads):
            t.join(max(0.0, deadline - time.monotonic()))
        return not any(t.is_alive() for t in self._threads)

    def _guard(self, fn: Callable[..., None], *args: Any) -> None:
        try:
            fn(*args)
        except BaseException as exc:  # noqa: BLE001 - reported, never raised in a thread
            if self.error is None:
                self.error = exc
            log.error("video replay stopped: %s", exc)
            self._stop.set()

    # --------------------------------------------------------- camera threads
    def _end_s(self) -> float:
        return math.inf if self.duration_s is None else self.t0_s + self.duration_s

    def _put(self, q: queue.Queue, item: VideoItem | None) -> bool:
        while not self._stop.is_set():
            try:
                q.put(item, timeout=0.2)
                return True
            except queue.Full:
                continue
        return False

    def _camera(self, sensor: str) -> None:
        q = self._queues[sensor]
        cam = self.site.sensor(sensor).camera
        classifier = BlobClassifier(cam, self.site.geolocator())
        mask_path = site_mask_path(self.site.root, sensor)
        shown_every = self.speed / self.frame_hz  # replay seconds between shown frames
        last_shown = -math.inf
        clip_no = 0
        t_busy = time.perf_counter()
        try:
            for k in itertools.count() if self.loop else range(1):
                for j, clips in enumerate(self.clips):
                    clip_no += 1
                    clip = clips.get(sensor)
                    shift = self.t0_s + k * self.period_s + self.offsets[j] - self.spans[j][0]
                    if clip is None:
                        continue
                    if shift + self.spans[j][0] >= self._end_s():
                        return
                    items = self._clip_items(clip, classifier, mask_path, shift, clip_no)
                    for t, recs, frame in items:
                        if t >= self._end_s():
                            return
                        jpeg = None
                        if frame is not None and t - last_shown >= shown_every - 1e-6:
                            last_shown = t
                            jpeg = encode_jpeg(frame.image, max_width=1280, quality=75)
                        self.n_frames[sensor] += 1
                        t_wait = time.perf_counter()
                        self.busy_s[sensor] += t_wait - t_busy
                        if not self._put(q, VideoItem(t, sensor, recs, jpeg)):
                            return
                        t_busy = time.perf_counter()
        finally:
            self._put(q, None)

    def _clip_items(
        self, clip: VideoClip, classifier: BlobClassifier, mask_path: Any, shift: float, n: int
    ) -> Iterator[tuple[float, tuple[dict[str, Any], ...], Frame | None]]:
        """The clip's frames on the replay clock: time, detection records, decoded frame."""
        reader = VideoReader(clip.path, gray=False, threads=1)
        cam = self.site.sensor(clip.sensor).camera
        size = (cam.intrinsics.width, cam.intrinsics.height)
        if reader.size != size:
            raise VideoError(
                f"video {clip.path} is {reader.size[0]}x{reader.size[1]} but camera"
                f" {clip.sensor} is calibrated for {size[0]}x{size[1]}"
            )
        mask = load_mask(str(mask_path), reader.size) if mask_path.is_file() else None
        det = make_detector(self.detector, reader.size, fps=reader.fps, mask=mask)
        keep = FrameKeeper(reader, keep=64)
        pipe = VideoDetections(keep, det, clip.sensor, classifier)  # type: ignore[arg-type]
        base = n * LOCAL_ID_STRIDE
        for res in pipe.results():
            if res.index < 0:
                continue
            tau = res.t_s - clip.scenario_start_s
            t = round(tau + shift, 6)
            warming = clip.detect_from_s is not None and tau < clip.detect_from_s - 1e-6
            recs = () if warming else tuple(_record(d, t, base) for d in res.detections)
            yield t, recs, keep.frames.get(res.index)
            if self._stop.is_set():
                return

    # ----------------------------------------------------------------- player
    def _drain(self, sensor: str) -> Iterator[VideoItem]:
        q = self._queues[sensor]
        while not self._stop.is_set():
            try:
                item = q.get(timeout=0.2)
            except queue.Empty:
                continue
            if item is None:
                return
            yield item

    def _play(self) -> None:
        merged = heapq.merge(
            *(self._drain(s) for s in self.sensors), key=lambda i: (i.t_s, i.sensor)
        )
        item = next(merged, None)
        if item is None:
            return
        wall0, t_first = self.clock(), item.t_s

        def due(i: VideoItem) -> float:
            return wall0 + (i.t_s - t_first) / self.speed

        while item is not None and not self._stop.is_set():
            wait = due(item) - self.clock()
            if wait > 0 and self._stop.wait(wait):
                return
            if -wait > self.max_lag_s:
                self.late_s = max(self.late_s, -wait)
                self.n_clock_moves += 1
                wall0 += -wait
                if self.n_clock_moves == 1:
                    busy = self.stats()["busy_ms_per_frame"]
                    log.warning(
                        "video replay cannot keep up at %g x: decoding and detecting take"
                        " %s ms a frame per camera; it runs slower (a lower --speed keeps up)",
                        self.speed,
                        "/".join(f"{v:.0f}" for v in busy.values()),
                    )
            elif wait < 0:
                self.late_s = max(self.late_s, -wait)
            batch = [item]
            item = next(merged, None)
            now = self.clock()
            while item is not None and due(item) <= now:
                batch.append(item)
                item = next(merged, None)
            self._send(batch)

    def _send(self, batch: list[VideoItem]) -> None:
        records = [r for i in batch for r in i.records]
        if records:
            self.ingest(records)
            self.n_batches += 1
            self.n_detections += len(records)
        newest: dict[str, VideoItem] = {}
        for i in batch:
            if i.jpeg is not None:
                newest[i.sensor] = i
        for s, i in newest.items():
            boxes = [r["bbox"] for r in i.records]
            self.book.put(s, i.jpeg, i.t_s, boxes, check=False)  # type: ignore[arg-type]
            self.n_shown += 1
        self.t_s = batch[-1].t_s

    def stats(self) -> dict[str, Any]:
        """Counts, the player's lateness and each camera's busy time per frame."""
        return {
            "frames": dict(self.n_frames),
            "detections": self.n_detections,
            "batches": self.n_batches,
            "shown": self.n_shown,
            "late_s": self.late_s,
            "clock_moves": self.n_clock_moves,
            "busy_ms_per_frame": {
                s: 1000 * self.busy_s[s] / max(self.n_frames[s], 1) for s in self.sensors
            },
        }


def _record(d: Any, t_s: float, base: int) -> dict[str, Any]:
    bbox = [float(x) for x in d.bbox]
    rec: dict[str, Any] = {"t": t_s, "sensor": d.sensor, "bbox": bbox, "class": d.cls}
    if d.score is not None:
        rec["score"] = d.score
    if d.local_id is not None:
        rec["local_id"] = base + int(d.local_id)
    return rec
