"""Starting the video replay from the server's settings (called by the app's lifespan)."""

from __future__ import annotations

import logging
from typing import Any

from demtrack.core.errors import DemtrackError
from demtrack.core.io.times import format_utc

from ..replay import LOOP_GAP_S, start_time_after
from ..state import ConsoleState
from .frame_book import FrameBook
from .replay_video import VideoReplay
from .source import VideoClip, VideoScenarioSource

__all__ = ["check_video_source", "start_video_replay"]

log = logging.getLogger("demtrack.server")


def check_video_source(names: list[str], source: Any) -> None:
    """Refuse, in one line, a video replay its source cannot play.

    Raises
    ------
    DemtrackError
        The source makes no videos, or one of ``names`` cannot be played from video.
    """
    if not isinstance(source, VideoScenarioSource):
        raise DemtrackError(
            "cannot replay from video: the scenario source handed to create_app makes no"
            " videos (demtrack serve --video and demtrack demo --video hand the sample site's)"
        )
    playable = list(source.video_names)
    bad = [n for n in names if n not in playable]
    if bad:
        raise DemtrackError(
            f"scenario {bad[0]!r} cannot be played from video; --video plays {', '.join(playable)}"
        )


def start_video_replay(
    state: ConsoleState, source: VideoScenarioSource, book: FrameBook, after: Any = None
) -> VideoReplay:
    """Start replaying ``settings.replay`` from video into the pipeline and ``book``.

    The clips are made (rendered on a first run) in the replay's thread, each fixed
    camera's for each scenario; ``after`` (``app.state.replay_after``) runs once they are.
    """
    settings, site = state.settings, state.site
    t0 = start_time_after(state.store.last_times())
    if settings.replay_start_s is not None:  # real UTC times, never before what is stored
        t0 = max(t0, float(settings.replay_start_s))
    names = list(settings.replay)
    sensors = [s.id for s in site.sensors.values() if not getattr(s, "active", False)]

    def clips() -> list[dict[str, VideoClip]]:
        made = [{s: source.video(site, name, s) for s in sensors} for name in names]
        return [{s: c for s, c in m.items() if c is not None} for m in made]

    replay = VideoReplay(
        site,
        clips,
        state.pipeline.ingest,
        book,
        t0_s=t0,
        speed=settings.replay_speed,
        frame_hz=settings.replay_frame_hz,
        loop=settings.replay_loop,
        gap_s=LOOP_GAP_S,
        duration_s=settings.replay_duration_s or None,
        after=after,
    )
    log.info(
        "replaying %s from video from %s at %g x",
        ", ".join(names),
        format_utc(t0, 0),
        settings.replay_speed,
    )
    return replay.start()
