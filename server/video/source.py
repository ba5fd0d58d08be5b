"""What a video replay needs from its caller: each scenario's video from each camera.

The server renders nothing itself (it never imports the sample-site generator): the
caller of :func:`~demtrack.server.app.create_app` hands a scenario source that also
fits :class:`VideoScenarioSource` (``demtrack.samplesite.video_cache.SampleVideos`` for
the sample site: it renders each video once into ``<site>/videos/`` and reads it back
after). A clip's frames carry UTC times (the reader's, from the file); ``scenario_start_s``
maps them back to scenario time, which the replay moves to its own clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from demtrack.core.site.folder import Site

from ..scenario_source import ReplayScenario

__all__ = ["VideoClip", "VideoScenarioSource"]


@dataclass(frozen=True)
class VideoClip:
    """One camera's video of one scenario.

    Attributes
    ----------
    path : Path
        The video file (any container PyAV reads, with a start time in its metadata).
    sensor : str
        The camera.
    scenario_start_s : float
        UNIX seconds (UTC) of scenario time 0 in the file's clock: a frame read at UTC
        ``t`` is scenario time ``t - scenario_start_s``.
    t_from_s, t_to_s : float
        Scenario seconds the clip covers (first and last frame).
    detect_from_s : float, optional
        Scenario seconds before which the detector only learns the scene: its detections
        of earlier frames are not sent (a background model's first frames are mostly
        false alarms; a camera gateway warms up the same way). None: send all.
    """

    path: Path
    sensor: str
    scenario_start_s: float
    t_from_s: float
    t_to_s: float
    detect_from_s: float | None = None


@runtime_checkable
class VideoScenarioSource(Protocol):
    """A scenario source whose scenarios can be played from video."""

    @property
    def video_names(self) -> Sequence[str]:
        """The scenario names :meth:`video` can make videos of."""
        ...

    def make(
        self, site: Site, name: str, *, seed: int, rate_hz: float | None = None
    ) -> ReplayScenario:
        """The scenario itself (as :class:`~..scenario_source.ScenarioSource`)."""
        ...

    def video(self, site: Site, name: str, sensor: str) -> VideoClip | None:
        """``sensor``'s video of scenario ``name`` (made once, then reused); None: no video."""
        ...
