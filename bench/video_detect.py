"""Benchmark: ``demtrack watch``'s detection path on a 1280x720 video, on one core.

A 1280x720 H.264 clip is written first (the sample site's still of ``--sensor`` as the
background when the site is there, else a textured synthetic one, with sensor noise and
a person- and a car-sized body moving), then timed, every stage on one thread
(OpenCV, the decoder, numba):

- **watch path**: decode (grey) + VSAM (full resolution, no downscaling) + classify
  (metric size at the geolocated foot on the site's DEM, or image cues without a site) +
  the blob tracker, i.e. :class:`~demtrack.core.video.pipeline.VideoDetections`;
- **VSAM alone** and **OpenCV MOG2 alone** (``apply`` on the same decoded frames, grey and
  RGB), the peer.

Printed: frames/s of each, by the process's CPU time (every stage is on one thread, so
that is one dedicated core's rate even on a shared machine; ``--wall`` for wall-clock),
and the ratios to MOG2 measured in the same run. The issue's bar is the watch path at
25 frames/s or more.

Usage: ``demtrack bench video [--frames 250] [--site DIR] [--sensor cam1] [--video FILE]``.
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

__all__ = ["main", "write_bench_clip"]

W, H = 1280, 720


def write_bench_clip(path: Path, n_frames: int, background: np.ndarray | None = None) -> Path:
    """A 1280x720 grey-world clip with two moving bodies (H.264, crf 18), ``creation_time`` set."""
    import av
    import cv2

    rng = np.random.default_rng(0)
    if background is None:
        noise = rng.normal(0, 1, (H // 8, W // 8)).astype(np.float32)
        tex = cv2.resize(cv2.GaussianBlur(noise, (0, 0), 1.2), (W, H))
        background = 110 + 60 * (tex - tex.min()) / (np.ptp(tex) + 1e-9)
    base = np.asarray(background, np.float32)
    bank = rng.normal(0, 2.0, (5, H, W)).astype(np.float32)
    c = av.open(str(path), "w")
    c.metadata["creation_time"] = "2026-12-01T14:30:00.000000Z"
    s = c.add_stream("libx264", rate=25)
    s.width, s.height, s.pix_fmt = W, H, "yuv420p"
    s.options = {"crf": "18", "preset": "ultrafast", "bf": "0"}
    for k in range(n_frames):
        img = base + bank[k % 5]
        x = 100 + (3 * k) % 1000
        cv2.rectangle(img, (x, 520), (x + 12, 556), 40, -1)  # a person, 12 x 36 px
        xc = 1100 - (5 * k) % 1000
        cv2.rectangle(img, (xc, 470), (xc + 80, 505), 200, -1)  # a car, 80 x 35 px
        rgb = np.repeat(np.clip(img, 0, 255).astype(np.uint8)[:, :, None], 3, axis=2)
        frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
        frame.pts, frame.time_base = k, Fraction(1, 25)
        for p in s.encode(frame):
            c.mux(p)
    for p in s.encode():
        c.mux(p)
    c.close()
    return path


def _clock() -> float:
    """Seconds of this process's CPU (or wall-clock seconds with ``--wall``).

    Every stage runs on one thread, so CPU time is what one dedicated core needs, even
    when other jobs share the machine.
    """
    return time.perf_counter() if _WALL else time.process_time()


_WALL = False


def _rate(n: int, seconds: float) -> float:
    return n / seconds if seconds > 0 else float("inf")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; prints frames/s and ratios."""
    parser = argparse.ArgumentParser(prog="demtrack bench video", description=__doc__)
    parser.add_argument(
        "--frames", type=int, default=250, help="frames written, and timed by the stages alone"
    )
    parser.add_argument("--site", type=Path, default=Path("sample_site") / "site")
    parser.add_argument("--sensor", default="cam1")
    parser.add_argument("--video", type=Path, help="time this 1280x720 video instead")
    parser.add_argument("--wall", action="store_true", help="wall-clock time, not CPU time")
    args = parser.parse_args(argv)
    global _WALL
    _WALL = bool(args.wall)

    import cv2
    import numba

    from demtrack.core.video.blob_tracker import BlobTracker
    from demtrack.core.video.blobs import Blob
    from demtrack.core.video.classify import BlobClassifier
    from demtrack.core.video.detector import VsamDetector
    from demtrack.core.video.pipeline import VideoDetections
    from demtrack.core.video.reader import Frame, VideoReader

    cv2.setNumThreads(1)
    numba.set_num_threads(1)
    site = None
    if (args.site / "site.json").is_file():
        from demtrack.core.site.folder import load_site

        site = load_site(args.site)
    with tempfile.TemporaryDirectory() as tmp:
        video = args.video
        if video is None:
            bg = None
            if site is not None and site.sensor(args.sensor).image_path is not None:
                still = cv2.imread(str(site.sensor(args.sensor).image_path), cv2.IMREAD_GRAYSCALE)
                bg = still if still is not None and still.shape == (H, W) else None
            video = write_bench_clip(Path(tmp) / "bench.mp4", args.frames, bg)
        if site is not None:
            cam = site.sensor(args.sensor).camera
            classifier = BlobClassifier(cam, site.geolocator())
            # compile the ray caster before timing
            classifier.classify([Blob.from_box((600.0, 500.0, 612.0, 536.0))])
            how = f"metric size on {site.name}'s DEM ({args.sensor})"
        else:
            classifier = BlobClassifier()
            how = "image cues (no site found)"

        reader = VideoReader(video, gray=True, threads=1)
        pipe = VideoDetections(
            reader, VsamDetector(reader.size, fps=reader.fps), "cam", classifier, BlobTracker()
        )
        t0 = _clock()
        n_det = n = 0
        for res in pipe.results():
            n += res.index >= 0
            n_det += len(res.detections)
        watch_s = _clock() - t0

        t0 = _clock()
        # the stages alone on the first --frames frames, held in memory
        head = itertools.islice(VideoReader(video, gray=True, threads=1), args.frames)
        gray = [f.image for f in head]
        decode_s = _clock() - t0
        rgb = [f.image for f in itertools.islice(VideoReader(video, threads=1), args.frames)]

        vsam = VsamDetector(reader.size, fps=reader.fps)
        frames = [Frame(k, k / 25, g) for k, g in enumerate(gray)]
        t0 = _clock()
        for f in frames:
            vsam.detect(f)
        vsam_s = _clock() - t0

        mog = cv2.createBackgroundSubtractorMOG2(detectShadows=True)
        t0 = _clock()
        for g in gray:
            mog.apply(g)
        mog_gray_s = _clock() - t0
        mog = cv2.createBackgroundSubtractorMOG2(detectShadows=True)
        t0 = _clock()
        for im in rgb:
            mog.apply(im)
        mog_rgb_s = _clock() - t0

    mog_fps = _rate(len(gray), mog_gray_s)
    watch_fps = _rate(n, watch_s)
    clock = "wall-clock" if _WALL else "CPU time of the one thread (load-independent)"
    print(f"video: {reader.size[0]}x{reader.size[1]}, {n} frames; one thread everywhere; {clock}")
    print(f"classifier: {how}; VSAM at full resolution (no downscaling)")
    rows = [
        ("watch path (decode + VSAM + classify + blob tracker)", watch_fps),
        ("  decode alone (grey)", _rate(len(gray), decode_s)),
        ("  VSAM alone on the decoded frames", _rate(len(gray), vsam_s)),
        ("OpenCV MOG2 alone on the same frames (grey)", mog_fps),
        ("OpenCV MOG2 alone on the same frames (RGB)", _rate(len(rgb), mog_rgb_s)),
    ]
    for name, fps in rows:
        print(f"{name:<54} {fps:7.1f} frames/s")
    print(f"watch path detections: {_rate(n_det, watch_s):.1f} detections/s")
    print(
        f"ratio watch path / MOG2 alone (grey): {watch_fps / mog_fps:.2f}; "
        f"VSAM alone / MOG2 alone: {_rate(len(gray), vsam_s) / mog_fps:.2f}"
    )
    print(f"bar: watch path >= 25 frames/s: {'met' if watch_fps >= 25 else 'NOT met'} in this run")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
