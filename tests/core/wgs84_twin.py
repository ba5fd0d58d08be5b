"""An independent WGS84 twin for tests: geodetic -> ECEF -> local ENU by the textbook formulas.

NIMA TR8350.2 constants, written out here so that tests of ``demtrack.core.geo.geodesy`` and of
everything built on it (CRS imports, surveyed camera poses) compare against code that does not
share a line with the implementation.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ecef", "enu", "r_enu_ecef"]

_A = 6378137.0
_F = 1.0 / 298.257223563
_E2 = _F * (2.0 - _F)


def ecef(lat_deg, lon_deg, h_m):
    """Earth-centred, earth-fixed (m), shape ``(3, ...)``."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = _A / np.sqrt(1.0 - _E2 * np.sin(lat) ** 2)
    return np.stack(
        [
            (n + h_m) * np.cos(lat) * np.cos(lon),
            (n + h_m) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - _E2) + h_m) * np.sin(lat),
        ]
    )


def r_enu_ecef(lat_deg, lon_deg):
    """Rotation taking ECEF vectors into east, north, up at a point, shape ``(3, 3)``."""
    p, lam = np.radians(lat_deg), np.radians(lon_deg)
    return np.array(
        [
            [-np.sin(lam), np.cos(lam), 0.0],
            [-np.sin(p) * np.cos(lam), -np.sin(p) * np.sin(lam), np.cos(p)],
            [np.cos(p) * np.cos(lam), np.cos(p) * np.sin(lam), np.sin(p)],
        ]
    )


def enu(lat_deg, lon_deg, h_m, anchor):
    """Local ENU (m) of geodetic points in the frame anchored at ``anchor`` (lat, lon, h)."""
    d = ecef(lat_deg, lon_deg, h_m) - ecef(*anchor).reshape((3,) + (1,) * np.ndim(lat_deg))
    return np.tensordot(r_enu_ecef(*anchor[:2]), d, axes=1)
