"""Building the head controller for the running server, and its pose feed.

:func:`start_heads` is called in the app's lifespan once the pipeline has replayed the
store (so a restored ``follow`` finds its track): one adapter per active sensor
(:mod:`.config`), the journal beside the database, the pose feed into
``state.poses.accept`` (the pose ingest: stored, streamed as ``sensor_pose``, used to
geolocate the detections of that moment).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from demtrack.core.camera.pose_series import PoseSample

from .adapter import HeadStatus
from .config import active_head_configs, build_adapter
from .controller import HeadController, HeadUnit, PoseFeed
from .journal import HeadJournal

__all__ = ["check_heads", "journal_path", "pose_feed", "start_heads"]

log = logging.getLogger("demtrack.server")


def journal_path(db_path: Path) -> Path:
    """``<db>.heads.jsonl``: the heads' journal beside the database."""
    return db_path.with_name(db_path.name + ".heads.jsonl")


def pose_feed(state: Any) -> PoseFeed | None:
    """``feed(sensor_id, statuses)`` into ``state.poses.accept`` (None without one)."""
    poses = getattr(state, "poses", None)
    if poses is None:
        return None
    site = state.site

    def feed(sensor_id: str, statuses: Sequence[HeadStatus]) -> None:
        # The field of view only where the lens has a zoom table: a fixed lens is its
        # calibration, whatever a simulated head's zoom axis says.
        zoomed = getattr(site.sensor(sensor_id), "zoom", None) is not None
        samples = [
            PoseSample(s.t_s, s.pan_deg, s.tilt_deg, hfov_deg=s.hfov_deg if zoomed else None)
            for s in statuses
        ]
        poses.accept(sensor_id, samples)

    return feed


def check_heads(site: Any, settings: Any) -> None:
    """Build (without starting or connecting) every adapter: a bad entry raises one line.

    Called by :func:`demtrack.server.app.check_startup`, before uvicorn runs.
    """
    if settings.heads != "off":
        for config in active_head_configs(site):
            build_adapter(site, config)


def start_heads(state: Any) -> HeadController | None:
    """The started controller of the site's active heads (None: ``heads=off`` or none)."""
    settings = state.settings
    if settings.heads == "off":
        return None
    configs = active_head_configs(state.site)
    if not configs:
        return None
    units = [
        HeadUnit(c.sensor_id, build_adapter(state.site, c), c.limits, str(c.adapter["kind"]))
        for c in configs
    ]
    ctl = HeadController(
        state.site,
        units,
        state.pipeline,
        pose_feed(state),
        HeadJournal(journal_path(settings.resolved_db_path)),
        period_s=settings.heads_period_s,
        lead_s=settings.reorder_lag_s,
    )
    log.info("driving %d pan-tilt-zoom heads: %s", len(units), ", ".join(ctl.units))
    return ctl.start()
