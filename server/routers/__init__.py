"""One router per resource."""

from __future__ import annotations

from . import detections, geolocate, health, sensors, site, stream, tracks

__all__ = ["detections", "geolocate", "health", "sensors", "site", "stream", "tracks"]
