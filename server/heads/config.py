"""One adapter per active sensor, from the site's manifest.

A sensor is *active* (on a pan-tilt-zoom head the server drives) when its ``site.json``
entry says ``"active": true``. Its limits are ``"slew_limits"`` (the field names of
:class:`~demtrack.core.camera.head_motion.SlewLimits`) and its adapter
``"head_adapter"``::

    "head_adapter": {"kind": "onvif", "url": "http://cam/onvif/ptz_service",
                     "profile": "Profile_1", "user": "admin",
                     "password_env": "CAM1_ONVIF_PASSWORD", "timeout_s": 2,
                     "pan_range_deg": [-180, 180], "tilt_range_deg": [-90, 30],
                     "hfov_deg": [60, 3], "zoom_scale": "focal"}

``{"kind": "sim"}`` (or no entry) is a simulated head starting at the sensor's stored
pan and tilt; ``{"kind": "external"}`` is a head the server does not drive (its gateway
posts its poses to ``POST /api/sensors/{id}/poses``), so it gets no unit. The password
comes from the environment variable ``password_env`` names, never from the manifest.
``active`` and ``slew_limits`` are the loaded :class:`~demtrack.core.site.folder.Sensor`'s;
``head_adapter`` is read here from the raw manifest entry.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from demtrack.core.camera.head_motion import SlewLimits
from demtrack.core.errors import DemtrackError, SiteError
from demtrack.core.site.folder import Site

from .adapter import HeadAdapter
from .onvif import OnvifHead, OnvifMapping
from .simulated import SimulatedHead

__all__ = ["KINDS", "HeadConfig", "active_head_configs", "build_adapter"]

#: ``head_adapter.kind`` values: driven by the server (sim, onvif) or not (external).
KINDS = ("sim", "onvif", "external")


@dataclass(frozen=True)
class HeadConfig:
    """An active sensor's head: its limits and adapter entry (``{"kind": "sim"}`` default)."""

    sensor_id: str
    limits: SlewLimits
    adapter: Mapping[str, Any]


def _entries(site: Site) -> dict[str, Mapping[str, Any]]:
    try:
        doc = json.loads((site.root / "site.json").read_text("utf-8"))
    except (OSError, ValueError) as exc:
        raise SiteError(f"site.json cannot be read for the heads: {exc}") from None
    return {
        e["id"]: e
        for e in doc.get("sensors", [])
        if isinstance(e, Mapping) and isinstance(e.get("id"), str)
    }


def active_head_configs(site: Site) -> list[HeadConfig]:
    """The site's active sensors, in manifest order, with their limits and adapters."""
    out = []
    entries = _entries(site)
    for sensor in site.sensors.values():
        entry = entries.get(sensor.id, {})
        active = getattr(sensor, "active", None)
        if not (active if active is not None else entry.get("active") is True):
            continue
        raw_limits = getattr(sensor, "slew_limits", None) or entry.get("slew_limits")
        try:
            limits = SlewLimits.from_dict(raw_limits)
        except DemtrackError as exc:
            raise SiteError(f"site.json: sensor {sensor.id!r}: {exc}") from None
        adapter = entry.get("head_adapter") or {"kind": "sim"}
        if not isinstance(adapter, Mapping) or adapter.get("kind") not in KINDS:
            raise SiteError(
                f"site.json: sensor {sensor.id!r}: head_adapter.kind must be one of"
                f" {', '.join(KINDS)}"
            )
        if adapter["kind"] == "external":
            continue
        out.append(HeadConfig(sensor.id, limits, dict(adapter)))
    return out


def build_adapter(
    site: Site, config: HeadConfig, clock: Callable[[], float] | None = None
) -> HeadAdapter:
    """The adapter a :class:`HeadConfig` names (a simulated head at the stored pose)."""
    sensor = site.sensor(config.sensor_id)
    a = config.adapter
    if a.get("kind") == "onvif":
        where = f"site.json: sensor {config.sensor_id!r}: head_adapter"
        if not isinstance(a.get("url"), str) or not isinstance(a.get("profile"), str):
            raise SiteError(f"{where} needs 'url' and 'profile' strings")
        password = None
        if a.get("password_env"):
            password = os.environ.get(str(a["password_env"]))
            if password is None:
                raise SiteError(f"{where}: environment variable {a['password_env']} is not set")
        try:
            mapping = OnvifMapping.from_dict(a)
            return OnvifHead(
                a["url"],
                a["profile"],
                mapping,
                user=a.get("user"),
                password=password,
                timeout_s=float(a.get("timeout_s", 2.0)),
            )
        except DemtrackError as exc:
            raise SiteError(f"{where}: {exc}") from None
    kwargs: dict[str, Any] = {} if clock is None else {"clock": clock}
    return SimulatedHead(
        config.limits, sensor.pan_deg, sensor.tilt_deg, _hfov_of(sensor, config.limits), **kwargs
    )


def _hfov_of(sensor: Any, limits: SlewLimits) -> float:
    """The sensor's fixed lens's horizontal field of view (degrees), inside the limits."""
    intr = sensor.head.intrinsics
    hfov = math.degrees(2.0 * math.atan(intr.width / (2.0 * intr.fx)))
    return max(limits.hfov_min_deg, min(limits.hfov_max_deg, hfov))
