"""Write a sample video (H.264 MP4) and its true boxes (``FILE.truth.jsonl``).

The MP4 (PyAV, libx264, yuv420p) holds the frames at the scenario's frame rate. Its
``creation_time`` tag is the UTC of presentation time 0, a whole second (MP4 keeps whole
seconds); each frame's presentation timestamp (ms) is its scenario time minus that, so
``creation_time + pts`` is the frame's UTC. The truth file beside it is JSON Lines: a
header (``format: demtrack.video-truth``, version 1) and one line per frame::

    {"frame": 0, "t_s": 1796135395.0, "t_utc": "2026-12-01T14:29:55.000Z",
     "targets": [{"target_id": 1, "class": "vehicle", "bbox": [u_min, v_min, u_max,
     v_max], "visible_fraction": 0.93, "cut": false, "counted": true}]}

``t_s`` is UNIX seconds UTC; ``bbox`` is in pixels (pixel (0, 0) is the centre of the
top-left pixel; the box covers the drawn pixels' squares), null when the target is in
view but hidden; ``counted`` marks the boxes a detector must find (see
:mod:`.video_render`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

from demtrack.core.errors import InputFileError, SiteError
from demtrack.core.io.times import format_utc, parse_iso_time
from demtrack.core.site.folder import Site

from .scenarios import SCENARIOS, ScenarioParams, site_world, true_cameras
from .video_render import BORDER_PX, MIN_VISIBLE, FrameRenderer, RenderLook, frame_times
from .video_scene import camera_scene

__all__ = [
    "TRUTH_FORMAT",
    "VideoReport",
    "VideoTruth",
    "read_video_truth",
    "truth_path_for",
    "write_sample_video",
]

TRUTH_FORMAT = "demtrack.video-truth"
#: The video starts this long before the scenario's first motion (s): a detector's
#: background model has the scene (swaying crowns included) to learn first, as a camera
#: that was running before; :mod:`.video_eval` scores from the first motion on.
LEAD_IN_S = 15.0


@dataclass(frozen=True)
class VideoReport:
    """What :func:`write_sample_video` wrote."""

    video: Path
    truth: Path
    frames: int
    boxes: int
    seconds: float

    @property
    def frames_per_s(self) -> float:
        """Rendering and encoding speed (frames/s)."""
        return self.frames / self.seconds if self.seconds > 0 else math.inf


@dataclass(frozen=True)
class VideoTruth:
    """A truth file read back: its header and its frames (dicts as written)."""

    header: dict[str, Any]
    frames: list[dict[str, Any]]

    @property
    def sensor(self) -> str:
        """The camera the video is from."""
        return str(self.header["sensor"])

    @property
    def start_s(self) -> float:
        """UNIX seconds of the scenario's time 0."""
        return float(self.header["scenario_start_s"])


def truth_path_for(video: str | Path) -> Path:
    """``FILE.truth.jsonl`` beside ``FILE.mp4``."""
    p = Path(video)
    return p.with_name(p.stem + ".truth.jsonl")


def write_sample_video(
    site: Site,
    scenario: str,
    sensor: str,
    out: str | Path,
    *,
    start_s: float,
    t_from_s: float | None = None,
    t_to_s: float | None = None,
    seed: int = 0,
    rate_hz: float | None = None,
    look: RenderLook | None = None,
    crf: int = 20,
    log: Callable[[str], None] | None = None,
) -> VideoReport:
    """Render ``scenario`` as seen by ``sensor`` into an MP4 and its truth file.

    Parameters
    ----------
    site : Site
        A generated sample site.
    scenario : str
        A key of :data:`~.scenarios.SCENARIOS`.
    sensor : str
        A camera of the site (drawn with its true mount yaw).
    out : path
        The ``.mp4`` to write; the truth goes to :func:`truth_path_for`.
    start_s : float
        UNIX seconds (UTC) of the scenario's time 0.
    t_from_s, t_to_s : float, optional
        Scenario seconds to render (default: from :data:`LEAD_IN_S` before the first
        motion to the end of the last).
    seed : int
        Seed of the noise, sway and drift.
    rate_hz : float, optional
        Frame rate (default the scenarios' 10 Hz).
    look : RenderLook, optional
        Noise, drift and sway.
    crf : int
        libx264 constant rate factor (lower: larger, closer to the render).
    log : callable, optional
        Receives progress lines.

    Raises
    ------
    SiteError
        Unknown scenario or sensor, or an empty time span.
    """
    import av

    if scenario not in SCENARIOS:
        raise SiteError(f"unknown scenario {scenario!r}; known: {', '.join(sorted(SCENARIOS))}")
    if sensor not in site.sensors:
        raise SiteError(f"unknown sensor {sensor!r}; the site has {', '.join(site.sensors)}")
    rate = ScenarioParams().rate_hz if rate_hz is None else float(rate_hz)
    world = site_world(site)
    targets = SCENARIOS[scenario](world)
    t_first = min(t.motion.t_start for t in targets)
    t_last = max(t.motion.t_end for t in targets)
    t0 = t_first - LEAD_IN_S if t_from_s is None else float(t_from_s)
    t1 = t_last if t_to_s is None else float(t_to_s)
    times = frame_times(t0, t1, rate)
    if not len(times):
        raise SiteError(f"no frames between t = {t0:g} s and {t1:g} s")
    say = log or (lambda _m: None)
    clock = time.perf_counter()
    camera = true_cameras(site)[sensor]
    scene = camera_scene(site, world, camera)
    say(f"{sensor}: static view rendered in {time.perf_counter() - clock:.1f} s")
    renderer = FrameRenderer(scene, world, targets, seed=seed, look=look)
    out = Path(out)
    truth_file = truth_path_for(out)
    created_s = float(math.floor(start_s + t0))
    header = {
        "format": TRUTH_FORMAT,
        "version": 1,
        "scenario": scenario,
        "sensor": sensor,
        "seed": seed,
        "rate_hz": rate,
        "width": camera.intrinsics.width,
        "height": camera.intrinsics.height,
        "scenario_start_s": start_s,
        "scenario_start_utc": format_utc(start_s),
        "video_creation_utc": format_utc(created_s, 0),
        "t_from_s": t0,
        "t_first_motion_s": t_first,
        "t_to_s": float(times[-1]),
        "min_visible": MIN_VISIBLE,
        "border_px": BORDER_PX,
        "bbox": "u_min, v_min, u_max, v_max (px); pixel (0, 0) is the centre of the top-left"
        " pixel; the box covers the drawn pixels' squares",
    }
    clock = time.perf_counter()
    n_boxes = 0
    with av.open(str(out), "w") as container, truth_file.open("w", encoding="utf-8") as tf:
        container.metadata["creation_time"] = format_utc(created_s, 6)
        container.metadata["comment"] = f"demtrack sample video: {scenario}, {sensor}"
        stream = container.add_stream("libx264", rate=Fraction(rate).limit_denominator(1000))
        stream.width, stream.height = camera.intrinsics.width, camera.intrinsics.height
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": str(crf), "preset": "veryfast"}
        tf.write(json.dumps(header) + "\n")
        for k, (t, image, truth) in enumerate(renderer.frames(times)):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts = round((start_s + t - created_s) * 1000)
            frame.time_base = Fraction(1, 1000)
            for packet in stream.encode(frame):
                container.mux(packet)
            rows = [_truth_row(tt) for tt in truth]
            n_boxes += sum(r["counted"] for r in rows)
            t_utc = start_s + t
            line = {"frame": k, "t_s": round(t_utc, 6), "t_utc": format_utc(t_utc), "targets": rows}
            tf.write(json.dumps(line) + "\n")
            if (k + 1) % 200 == 0:
                say(f"{sensor}: frame {k + 1}/{len(times)}")
        for packet in stream.encode():
            container.mux(packet)
    return VideoReport(out, truth_file, len(times), n_boxes, time.perf_counter() - clock)


def _truth_row(tt: Any) -> dict[str, Any]:
    return {
        "target_id": tt.target_id,
        "class": tt.cls,
        "bbox": None if tt.bbox is None else [round(x, 2) for x in tt.bbox],
        "visible_fraction": tt.visible_fraction,
        "cut": tt.cut,
        "counted": tt.counted,
    }


def read_video_truth(path: str | Path) -> VideoTruth:
    """Read a ``FILE.truth.jsonl`` written by :func:`write_sample_video`.

    Raises
    ------
    InputFileError
        Missing, unreadable or not a video truth file.
    """
    p = Path(path)
    try:
        lines = p.read_text("utf-8").splitlines()
        docs = [json.loads(line) for line in lines if line.strip()]
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputFileError(f"cannot read the video truth {p}: {err}") from None
    if not docs or not isinstance(docs[0], dict) or docs[0].get("format") != TRUTH_FORMAT:
        raise InputFileError(f"{p} is not a demtrack video truth file ({TRUTH_FORMAT})")
    parse_iso_time(docs[0]["scenario_start_utc"], "scenario_start_utc")  # a sane header
    return VideoTruth(docs[0], docs[1:])
