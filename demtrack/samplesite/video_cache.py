"""The sample site's scenarios as videos, for ``demtrack demo --video``.

:class:`SampleVideos` is the sample scenario source
(:data:`~.replay_source.SAMPLE_SCENARIOS`) that can also hand the console's video replay
each camera's video of a scenario (:class:`demtrack.server.video.source.VideoScenarioSource`
by shape). A video is rendered once by the sample-video renderer
(:func:`~.video_file.write_sample_video`, the same as ``demtrack sample-video``) into
``<site>/videos/<scenario>-<sensor>.mp4`` with its truth file beside it, and reused while
both are there; the frames' UTC times run from :data:`RENDER_EPOCH_S` (scenario time 0),
which the replay maps onto its own clock. Only the fixed-camera trajectory scenarios
can be rendered (the renderer draws each camera at its mount pose): vehicle-run,
pedestrians, passing-vehicles.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from demtrack.core.errors import SiteError
from demtrack.core.site.folder import Site
from demtrack.server.video.source import VideoClip

from .replay_source import SAMPLE_SCENARIOS, SampleScenarios
from .scene_render import Scenario
from .video_file import read_video_truth, truth_path_for, write_sample_video

__all__ = ["RENDER_EPOCH_S", "VIDEO_SCENARIOS", "SampleVideos", "video_path"]

#: UTC of scenario time 0 in the rendered files (2027-01-15T08:00:00Z; any fixed time).
RENDER_EPOCH_S = 1_800_000_000.0
#: The scenarios the sample-video renderer can draw (fixed cameras).
VIDEO_SCENARIOS = ("vehicle-run", "pedestrians", "passing-vehicles")


def video_path(folder: Path, scenario: str, sensor: str) -> Path:
    """``<folder>/<scenario>-<sensor>.mp4``."""
    return Path(folder) / f"{scenario}-{sensor}.mp4"


@dataclass
class SampleVideos:
    """The sample scenarios, with videos rendered on demand (see the module docstring).

    Parameters
    ----------
    folder : Path, optional
        Where the videos live (default: ``<site>/videos``).
    lead_in_s : float
        Seconds rendered before the scenario's first motion, for the detector's background
        model to learn the scene (default 15, the renderer's).
    span_s : float, optional
        Render only this many seconds of each scenario from its start, e.g. for a short
        test; default: all of it. The cache file names say neither the span nor the lead-in:
        give such videos their own folder.
    sensors : tuple of str, optional
        Only these cameras have videos (the others play no part in the replay); default all.
    warm_up_s : float
        The detector's first seconds of each clip (at most the lead-in) only learn the
        scene: their detections are not sent (on the sample videos the background model's
        first 10 s give 2-10 false blobs a frame; nothing moves then anyway).
    log : callable
        Receives one line per rendered video (and the renderer's progress).
    base : SampleScenarios
        The scenarios themselves.
    """

    folder: Path | None = None
    lead_in_s: float = 15.0
    span_s: float | None = None
    sensors: tuple[str, ...] | None = None
    warm_up_s: float = 10.0
    log: Callable[[str], None] = field(default=lambda _line: None)
    base: SampleScenarios = SAMPLE_SCENARIOS
    rendered_s: dict[str, float] = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        """Every scenario name (the base source's)."""
        return self.base.names

    @property
    def video_names(self) -> tuple[str, ...]:
        """The scenarios that can be played from video."""
        return VIDEO_SCENARIOS

    @property
    def rate_hz(self) -> float:
        """The scenarios' frame rate (Hz)."""
        return self.base.rate_hz

    def make(self, site: Site, name: str, *, seed: int, rate_hz: float | None = None) -> Scenario:
        """The base source's scenario."""
        return self.base.make(site, name, seed=seed, rate_hz=rate_hz)

    def video(self, site: Site, name: str, sensor: str) -> VideoClip | None:
        """``sensor``'s video of ``name``: rendered now if missing, else the cached one.

        None for a camera not in :attr:`sensors`.

        Raises
        ------
        SiteError
            A scenario the renderer cannot draw, or an unknown sensor.
        """
        if name not in VIDEO_SCENARIOS:
            raise SiteError(
                f"scenario {name!r} cannot be played from video; --video plays"
                f" {', '.join(VIDEO_SCENARIOS)}"
            )
        if self.sensors is not None and sensor not in self.sensors:
            return None
        folder = Path(self.folder) if self.folder is not None else Path(site.root) / "videos"
        path = video_path(folder, name, sensor)
        truth = truth_path_for(path)
        if not (path.is_file() and truth.is_file()):
            folder.mkdir(parents=True, exist_ok=True)
            t_from = _first_motion(site, name) - float(self.lead_in_s)
            t_to = None if self.span_s is None else t_from + float(self.span_s)
            part = path.with_name(path.stem + ".part.mp4")
            clock = time.perf_counter()
            report = write_sample_video(
                site, name, sensor, part, start_s=RENDER_EPOCH_S, t_from_s=t_from, t_to_s=t_to,
                log=self.log,
            )  # fmt: skip
            truth_path_for(part).replace(truth)
            part.replace(path)
            took = time.perf_counter() - clock
            self.rendered_s[f"{name}-{sensor}"] = took
            self.log(
                f"rendered {path.name}: {report.frames} frames in {took:.1f} s"
                f" ({report.frames_per_s:.1f} frames/s)"
            )
        header = read_video_truth(truth).header
        return VideoClip(
            path, sensor, float(header["scenario_start_s"]),
            float(header["t_from_s"]), float(header["t_to_s"]),
            detect_from_s=float(header["t_from_s"]) + min(self.warm_up_s, float(self.lead_in_s)),
        )  # fmt: skip


def _first_motion(site: Site, name: str) -> float:
    """Scenario seconds of the first target's first motion."""
    from .scenarios import SCENARIOS, site_world

    targets = SCENARIOS[name](site_world(site))
    return min(t.motion.t_start for t in targets)
