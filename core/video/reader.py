"""Reading video with PyAV: files and live streams, each frame timed in UTC from its PTS.

A frame's time is never the decode wall clock. For a **file** it is the file's start
time (its ``creation_time`` metadata, or ``start_utc_s`` given by the caller, which wins)
plus the frame's presentation time after the first frame's. For a **live stream**
(``rtsp://``, ``rtsp``'s siblings, ``udp://``, ``tcp://``, ``http(s)://``, ``srt://``)
the start is the wall clock when the first packet arrived minus the stream's latency
``latency_s``, and each frame adds its PTS offset from the first.

Data streams (MISB ST 0601 KLV in drone and FMV video) come out as :class:`KlvPacket` in
the same demux pass (:meth:`VideoReader.items`), timed the same way.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import TimeFormatError, VideoError, VideoStallError
from ..io.times import parse_iso_time

__all__ = ["LIVE_SCHEMES", "Frame", "KlvPacket", "VideoReader", "is_live_source"]

#: URL schemes read as live streams (timed from the wall clock at the first packet).
LIVE_SCHEMES = ("rtsp", "rtsps", "rtmp", "udp", "tcp", "rtp", "srt", "http", "https")


@dataclass(frozen=True, eq=False)
class Frame:
    """One decoded video frame.

    Attributes
    ----------
    index : int
        0-based decode order index within the source.
    t_s : float
        Capture time, UNIX seconds UTC, from the frame's own presentation timestamp.
    image : ndarray
        ``(h, w, 3)`` uint8 RGB, or ``(h, w)`` uint8 grey when the reader was opened
        with ``gray=True``. Row 0 is the top of the image; pixel ``(0, 0)`` is the centre
        of the top-left pixel.
    """

    index: int
    t_s: float
    image: np.ndarray


@dataclass(frozen=True)
class KlvPacket:
    """One packet of a data stream (KLV), timed like the frames.

    ``t_s`` is UNIX seconds UTC from the packet's PTS (None where it has none); ``data``
    the raw bytes, possibly several KLV sets back to back.
    """

    t_s: float | None
    data: bytes


def is_live_source(source: str | Path) -> bool:
    """True for a URL whose scheme is one of :data:`LIVE_SCHEMES`."""
    text = str(source)
    scheme, sep, _ = text.partition("://")
    return bool(sep) and scheme.lower() in LIVE_SCHEMES


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


class VideoReader:
    """Frames of a video file or live stream, iterated in decode order.

    Parameters
    ----------
    source : str or Path
        A file, or a URL (see :data:`LIVE_SCHEMES`).
    start_utc_s : float, optional
        The file's first frame time (UNIX s UTC); overrides the metadata. Required for a
        file whose metadata has no ``creation_time``. For a live stream it replaces the
        wall clock at the first packet.
    gray : bool
        Decode to ``(h, w)`` grey (what the motion detectors use; cheaper than RGB).
    latency_s : float
        Live streams: seconds between capture and arrival, subtracted from the wall clock.
    timeout_s : float
        Live streams: opening and each read give up after this long (unreachable:
        :class:`VideoError`; stalled after it started: :class:`VideoStallError`).
    threads : int
        Decoder threads (0: PyAV's default; 1 for a one-core measurement).

    Raises
    ------
    VideoError
        One line: the file is missing, unreadable, has no video stream, or needs a start
        time (naming ``--start``); the stream is unreachable.
    """

    def __init__(
        self,
        source: str | Path,
        *,
        start_utc_s: float | None = None,
        gray: bool = False,
        latency_s: float = 0.0,
        timeout_s: float = 5.0,
        threads: int = 0,
    ) -> None:
        if start_utc_s is not None and not math.isfinite(float(start_utc_s)):
            raise VideoError(f"start time must be finite, got {start_utc_s!r}")
        if not (math.isfinite(float(latency_s)) and latency_s >= 0):
            raise VideoError(f"latency_s must be 0 or more, got {latency_s!r}")
        if not (math.isfinite(float(timeout_s)) and timeout_s > 0):
            raise VideoError(f"timeout_s must be positive, got {timeout_s!r}")
        self.source = str(source)
        self.live = is_live_source(source)
        self.gray = bool(gray)
        self.latency_s = float(latency_s)
        self.timeout_s = float(timeout_s)
        self.threads = int(threads)
        self._given_start = None if start_utc_s is None else float(start_utc_s)
        if not self.live and not Path(self.source).is_file():
            raise VideoError(f"video file not found: {self.source}")
        container = self._open()
        self._live_container: Any = None
        try:
            stream = self._video_stream(container)
            rate = stream.average_rate or stream.guessed_rate or stream.base_rate
            self.fps = float(rate) if rate else 25.0
            self.size: tuple[int, int] = (
                int(stream.codec_context.width),
                int(stream.codec_context.height),
            )
            self.n_frames: int | None = int(stream.frames) if stream.frames else None
            self.has_klv = any(s.type == "data" for s in container.streams)
            self.start_utc_s: float | None = self._file_start(container, stream)
        except BaseException:
            container.close()
            raise
        if self.live:  # a live stream is read on from this connection, not reopened
            self._live_container = container
        else:
            container.close()

    # ------------------------------------------------------------------ opening
    def _open(self) -> Any:
        import av

        options = {"rtsp_transport": "tcp"} if self.source.startswith("rtsp") else {}
        try:
            if self.live:
                return av.open(self.source, options=options, timeout=self.timeout_s)
            return av.open(self.source)
        except (av.error.FFmpegError, OSError) as exc:
            what = "stream unreachable" if self.live else "cannot read video"
            raise VideoError(f"{what}: {self.source}: {_one_line(exc)}") from None

    def _video_stream(self, container: Any) -> Any:
        if not container.streams.video:
            container.close()
            raise VideoError(f"no video stream in {self.source}")
        stream = container.streams.video[0]
        if self.threads:
            stream.codec_context.thread_count = self.threads
            if self.threads == 1:
                stream.thread_type = "NONE"
        else:
            stream.thread_type = "AUTO"
        return stream

    def _file_start(self, container: Any, stream: Any) -> float | None:
        if self._given_start is not None or self.live:
            return self._given_start
        for meta in (container.metadata, stream.metadata):
            text = meta.get("creation_time")
            if text:
                if text.endswith(("Z", "z")) or "+" in text[10:] or "-" in text[10:]:
                    try:
                        return parse_iso_time(text, "creation_time")
                    except TimeFormatError:
                        pass
                else:  # FFmpeg writes creation_time in UTC, sometimes without the Z
                    try:
                        return parse_iso_time(text + "Z", "creation_time")
                    except TimeFormatError:
                        pass
        raise VideoError(
            f"{self.source} has no start time in its metadata (creation_time); "
            "give the UTC time of its first frame with --start ISO (e.g. --start "
            "2026-12-01T14:30:00Z)"
        )

    # ---------------------------------------------------------------- iterating
    def __iter__(self) -> Iterator[Frame]:
        """The frames in decode order (KLV packets skipped)."""
        for item in self.items(klv=False):
            if isinstance(item, Frame):
                yield item

    def klv_packets(self) -> Iterator[KlvPacket]:
        """The data-stream packets alone (for a file: a pass that decodes no video)."""
        for item in self.items(frames=False):
            if isinstance(item, KlvPacket):
                yield item

    def items(self, *, frames: bool = True, klv: bool = True) -> Iterator[Frame | KlvPacket]:
        """Frames and KLV packets in demux order, timed alike.

        Raises
        ------
        VideoError
            A corrupt or truncated file (one line naming the frame reached).
        VideoStallError
            A live stream that delivered nothing for ``timeout_s``.
        """
        import av

        container, self._live_container = self._live_container or self._open(), None
        try:
            vstream = self._video_stream(container)
            wanted = [vstream] if frames else []
            if klv:
                wanted += [s for s in container.streams if s.type == "data"]
            if not wanted:
                return
            fmt = "gray" if self.gray else "rgb24"
            # PTS seconds of the start: the container's start time, else the first item's
            origin: list[float | None] = [
                None if container.start_time is None else container.start_time / 1e6
            ]
            start = [self.start_utc_s]
            index = 0
            packets = container.demux(*wanted)
            while True:
                try:
                    packet = next(packets)
                except StopIteration:
                    break
                except av.error.FFmpegError as exc:
                    if self.live:
                        raise VideoStallError(
                            f"stream {self.source} stalled or dropped after {index} frames "
                            f"({_one_line(exc)})"
                        ) from None
                    raise VideoError(
                        f"{self.source} is corrupt or truncated after {index} frames "
                        f"({_one_line(exc)})"
                    ) from None
                if packet.stream.type == "data":
                    if packet.size == 0:
                        continue
                    pts = None if packet.pts is None else float(packet.pts * packet.time_base)
                    yield KlvPacket(self._time(pts, origin, start), bytes(packet))
                    continue
                try:
                    decoded = packet.decode()
                except av.error.FFmpegError as exc:
                    if self.live:  # a damaged packet in a live stream: skip it
                        continue
                    raise VideoError(
                        f"{self.source} is corrupt at frame {index} ({_one_line(exc)})"
                    ) from None
                for vframe in decoded:
                    pts = None if vframe.pts is None else float(vframe.pts * vframe.time_base)
                    if pts is None:
                        pts = (origin[0] or 0.0) + index / self.fps
                    t_s = self._time(pts, origin, start)
                    yield Frame(index, t_s, vframe.to_ndarray(format=fmt))
                    index += 1
        finally:
            container.close()

    def _time(self, pts_s: float | None, origin: list[float | None], start: list[float | None]):
        """UNIX seconds of a PTS: the start plus the PTS offset from the first one."""
        if pts_s is None:
            return None
        if origin[0] is None:
            origin[0] = pts_s
        if start[0] is None:  # live: the wall clock at the first packet
            start[0] = time.time() - self.latency_s
            if self.live:
                origin[0] = pts_s
        return float(start[0]) + (pts_s - float(origin[0]))  # type: ignore[arg-type]
