"""``demtrack watch``: detect moving people and vehicles in a camera's video, live or filed.

Reads a video file or a live stream (PyAV), runs the detector (VSAM by default),
classifies and tracks the blobs (:mod:`demtrack.core.video`) and either posts the
detections to a console server (``--server URL --token T``) or writes JSON Lines
(``-o FILE.jsonl``) that ``demtrack track`` reads. KLV (MISB ST 0601) in the video
becomes pose telemetry, posted to ``/api/sensors/{id}/poses``.

Batches hold ``--batch-frames`` frames; a batch's key is the sensor, a digest of the
source and the batch's first frame index (and, for a live stream, the session's start),
so watching the same file again resends the same keys and the server stores nothing
twice. Throughput (frames/s, detections/s) and, for a file, a progress bar go to stderr.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path
from typing import Any

from .common import add_site_argument, non_negative, non_negative_int, positive, positive_int

__all__ = ["batch_key", "register"]


def batch_key(sensor: str, source: str, first_index: int, session: str = "") -> str:
    """The deterministic key of the batch starting at frame ``first_index``."""
    digest = hashlib.sha1(source.encode()).hexdigest()[:12]
    return f"video:{sensor}:{digest}{':' + session if session else ''}:{first_index}"


def _source_id(source: str) -> str:
    from demtrack.core.video.reader import is_live_source

    return source if is_live_source(source) else str(Path(source).resolve())


class _Progress:
    """Frames/s and detections/s, and a bar when the frame count is known (stderr)."""

    def __init__(self, total: int | None, enabled: bool) -> None:
        self.total, self.enabled = total, enabled
        self.t0 = time.perf_counter()
        self.frames = self.detections = 0
        self._last = 0.0

    def update(self, n_frames: int, n_detections: int) -> None:
        self.frames += n_frames
        self.detections += n_detections
        now = time.perf_counter()
        if self.enabled and now - self._last > 0.5:
            self._last = now
            sys.stderr.write("\r" + self.line() + " ")
            sys.stderr.flush()

    def line(self) -> str:
        dt = max(time.perf_counter() - self.t0, 1e-9)
        rate = f"{self.frames / dt:.1f} frames/s, {self.detections / dt:.1f} detections/s"
        if self.total:
            frac = min(self.frames / self.total, 1.0)
            bar = "#" * int(frac * 30)
            return f"[{bar:<30}] {frac:4.0%} {self.frames}/{self.total} frames, {rate}"
        return f"{self.frames} frames, {rate}"

    def done(self) -> str:
        if self.enabled and self._last:
            sys.stderr.write("\r" + " " * 100 + "\r")
        return self.line()


def _pose_records(klv_packets, site, sensor: str) -> list[dict[str, Any]]:
    """The pose file / ``/poses`` records of the KLV packets (:mod:`demtrack.core.io.pose_io`)."""
    from demtrack.core.errors import DemtrackError
    from demtrack.core.video.klv import iter_uas_datalink, to_pose_sample

    out = []
    for pk in klv_packets:
        try:
            for d in iter_uas_datalink(pk.data):
                p = to_pose_sample(d, site.frame, site.geoid, t_s=pk.t_s)
                rec: dict[str, Any] = {
                    "sensor": sensor, "t": p.t_s, "pan_deg": p.pan_deg, "tilt_deg": p.tilt_deg,
                }  # fmt: skip
                if p.hfov_deg is not None:
                    rec["hfov_deg"] = p.hfov_deg
                if p.roll_deg != 0.0:
                    rec["roll_deg"] = p.roll_deg
                if p.position_enu is not None:
                    rec.update(zip(("e_m", "n_m", "u_m"), p.position_enu, strict=True))
                if p.platform_ypr_deg is not None:
                    names = ("yaw_deg", "pitch_deg", "platform_roll_deg")
                    rec.update(zip(names, p.platform_ypr_deg, strict=True))
                out.append(rec)
        except DemtrackError as exc:  # a bad packet (checksum, a tilt past 90) is skipped
            print(f"demtrack watch: skipped a KLV packet: {exc}", file=sys.stderr)
    return out


def _watch_once(args, site, sink, progress, session: str, index0: int) -> int:
    """One reader session; returns the next frame index. Raises VideoError/VideoStallError."""
    from demtrack.commands.watch_sink import Batch, detection_record
    from demtrack.core.video.pipeline import video_detections

    pipe = video_detections(
        site,
        args.sensor,
        args.source,
        detector=args.detector,
        start_utc_s=args.start_s,
        mask=args.mask,
        latency_s=args.latency,
        metric=not args.image_only,
        timeout_s=args.timeout,
    )
    if progress.total is None and pipe.reader.n_frames:
        progress.total = pipe.reader.n_frames
    frames = getattr(args, "frame_poster", None)
    if frames is not None:  # --frames: keep the decoded frames the detections belong to
        from demtrack.server.video.frame_keeper import FrameKeeper

        pipe.reader = FrameKeeper(pipe.reader, keep=pipe.lag + 4, klv=True)  # type: ignore[assignment]
    source = _source_id(args.source)
    batch: Batch | None = None
    count = 0
    last = index0
    try:
        for res in pipe.results():
            index = index0 + res.index if res.index >= 0 else last
            last = index + 1
            if batch is None:
                batch = Batch(batch_key(args.sensor, source, index, session))
            batch.detections += [detection_record(d) for d in res.detections]
            if frames is not None and res.index >= 0 and res.index in pipe.reader.frames:
                image = pipe.reader.frames[res.index].image
                frames.offer(res.t_s, image, [d.bbox for d in res.detections])
            if res.klv:
                batch.poses += _pose_records(res.klv, site, args.sensor)
            count += 1
            progress.update(1 if res.index >= 0 else 0, len(res.detections))
            if count >= args.batch_frames:
                sink.put(batch)
                batch, count = None, 0
    finally:
        if batch is not None and (batch.detections or batch.poses):
            sink.put(batch)  # what was found before an error is still sent
    return last


def _run(args: argparse.Namespace) -> int:
    from demtrack.commands.watch_sink import JsonlSink, ServerSink
    from demtrack.core.errors import InputFileError, VideoError, VideoStallError
    from demtrack.core.io.times import parse_iso_time
    from demtrack.core.site.folder import load_site
    from demtrack.core.video.reader import is_live_source

    if (args.server is None) == (args.output is None):
        raise InputFileError("give --server URL (with --token) or -o FILE.jsonl, one of them")
    if args.output is not None and Path(args.output).suffix.lower() != ".jsonl":
        raise InputFileError(f"-o {args.output}: detections are written as .jsonl")
    args.start_s = None if args.start is None else parse_iso_time(args.start, "--start")
    site = load_site(args.site)
    site.sensor(args.sensor)
    live = is_live_source(args.source)

    def log(msg: str) -> None:
        sys.stderr.write(("\n" if not args.quiet and not live else "") + f"demtrack watch: {msg}\n")

    if args.frames and not args.server:
        raise InputFileError("--frames posts frames to a console server: give --server URL")
    if args.batch_frames is None:  # with frames, detections follow their frame closely
        args.batch_frames = 2 if args.frames else 25
    args.frame_poster = None
    sink: Any
    if args.server:
        sink = ServerSink(args.server, args.sensor, args.token, give_up_s=args.give_up, log=log)
    else:
        sink = JsonlSink(Path(args.output))
    progress = _Progress(None, enabled=not args.quiet)
    index, failures, delay = 0, 0, 1.0
    if args.frames:
        from demtrack.commands.watch_frames import FramePoster

        args.frame_poster = FramePoster(
            args.server, args.sensor, args.token, rate_hz=args.frame_rate, log=log
        )
    try:
        while True:
            session = f"{int(time.time() * 1000)}" if live else ""
            try:
                index = _watch_once(args, site, sink, progress, session, index)
                if not live:
                    break
                why = "stream ended"
            except VideoStallError as exc:
                why = str(exc)
            except VideoError as exc:
                if not live or progress.frames == 0:
                    raise
                why = str(exc)
            failures += 1
            if failures > args.reconnects:
                raise VideoError(f"{why}; gave up after {args.reconnects} reconnects")
            log(f"{why}; reconnecting in {delay:.0f} s")
            time.sleep(delay)
            delay = min(delay * 2, 30.0)
    finally:
        try:
            sink.close()
        finally:
            summary = progress.done()
            if args.frame_poster is not None:
                args.frame_poster.close()
    sent = f"{sink.n_detections} detections" + (f", {sink.n_poses} poses" if sink.n_poses else "")
    if args.frame_poster is not None:
        sent += f", {args.frame_poster.n_posted} frames"
    where = args.server or args.output
    print(f"watched {args.source}: {summary}; {sent} to {where}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``watch`` command."""
    p = sub.add_parser(
        "watch",
        help="detect people and vehicles in a camera's video file or live stream",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    add_site_argument(p)
    p.add_argument("--sensor", required=True, metavar="ID", help="the camera's sensor id")
    p.add_argument(
        "--source", required=True, metavar="FILE|URL", help="video file or rtsp://, udp://, ..."
    )
    p.add_argument(
        "--detector",
        default="vsam",
        metavar="NAME",
        help="vsam (default: Lipton et al.'s hybrid), mog2, knn, or onnx:MODEL.onnx",
    )
    p.add_argument(
        "--mask",
        type=Path,
        metavar="PNG",
        help="ignore mask, white = ignore (default: the site's masks/<sensor>.png if present)",
    )
    p.add_argument(
        "--start",
        metavar="ISO",
        help="UTC time of a file's first frame (when its metadata "
        "has no creation_time), e.g. 2026-12-01T14:30:00Z",
    )
    p.add_argument(
        "--latency",
        type=non_negative,
        default=0.0,
        metavar="S",
        help="live streams: seconds from capture to arrival (default 0)",
    )
    p.add_argument(
        "--timeout",
        type=positive,
        default=5.0,
        metavar="S",
        help="live streams: a stream silent this long has stalled (default 5)",
    )
    p.add_argument("--server", metavar="URL", help="console server to post to")
    p.add_argument("--token", metavar="T", help="the server's operator token")
    p.add_argument("-o", "--output", metavar="FILE.jsonl", help="write detections here instead")
    p.add_argument(
        "--batch-frames",
        type=positive_int,
        default=None,
        metavar="N",
        help="frames per posted batch (default 25; 2 with --frames)",
    )
    p.add_argument(
        "--reconnects",
        type=non_negative_int,
        default=10,
        metavar="N",
        help="live streams: reconnect this often after a stall (default 10)",
    )
    p.add_argument(
        "--give-up",
        type=positive,
        default=600.0,
        metavar="S",
        help="stop when the server is unreachable this long (default 600)",
    )
    p.add_argument(
        "--image-only",
        action="store_true",
        help="classify by image shape alone, not by size in metres on the DEM",
    )
    p.add_argument(
        "--frames",
        action="store_true",
        help="also post the video frames (JPEG, <= 1280 px wide) for the console's camera panel",
    )
    p.add_argument(
        "--frame-rate",
        type=positive,
        default=4.0,
        metavar="HZ",
        help="with --frames: most frames per second of video (default 4)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)
