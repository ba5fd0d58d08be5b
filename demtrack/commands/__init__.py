"""The CLI's commands, one module each (see :mod:`demtrack.cli`)."""

from __future__ import annotations

from . import (
    activity,
    archive,
    bench,
    build_dem,
    calibrate,
    dem_tiles,
    evaluate,
    evaluate_activity,
    evaluate_detections,
    gaps,
    geolocate,
    handoff,
    reprocess,
    sample_site,
    sample_video,
    scenario,
    serve,
    site_import,
    track,
    viewshed,
    watch,
)

__all__ = ["COMMANDS"]

#: Modules with ``register(subparsers)``, in help order.
COMMANDS = (
    sample_site,
    geolocate,
    build_dem,
    dem_tiles,
    site_import,
    calibrate,
    scenario,
    sample_video,
    track,
    reprocess,
    archive,
    evaluate,
    evaluate_activity,
    evaluate_detections,
    viewshed,
    activity,
    handoff,
    gaps,
    serve,
    watch,
    bench,
)
