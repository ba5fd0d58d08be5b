"""The CLI's commands, one module each (see :mod:`demtrack.cli`)."""

from __future__ import annotations

from . import bench, build_dem, calibrate, geolocate, sample_site

__all__ = ["COMMANDS"]

#: Modules with ``register(subparsers)``, in help order.
COMMANDS = (sample_site, geolocate, build_dem, calibrate, bench)
