"""Grid references the field uses: UTM and MGRS from WGS84 latitude/longitude, and back.

UTM (``32N 385734.2 6650941.7``): the zone (1-60, with the Norway and Svalbard
exceptions: 32V is widened to 3-12 E between 56 N and 64 N; between 72 N and 84 N only
31X, 33X, 35X and 37X exist), the latitude band letter (C-X, 8 degrees each, X 12) and the
easting/northing in metres on WGS84 (EPSG:326zz north, EPSG:327zz south, through PROJ).

MGRS (``32V KM 76979 58157``; the zone always in two digits, ``05Q``, as the ``mgrs``
package writes it) is the UTM coordinate written as the 100 km square's two letters (the
AA lettering scheme of WGS84: column sets A-H, J-R, S-Z by zone mod 3; row letters A-V
without I and O, offset by F in even zones) and the easting and northing inside the
square, **truncated** (not rounded) to the precision: a 1 m reference names the
south-west corner of the 1 m square the point lies in, as NGA's standard says.

The poles (south of 80 S, north of 84 N) are UPS, not UTM; this module refuses them with
one line (:class:`~demtrack.core.errors.GeodesyError`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from pyproj import Transformer

from ..errors import GeodesyError

__all__ = [
    "MGRS_MAX_LAT_DEG",
    "MGRS_MIN_LAT_DEG",
    "UtmRef",
    "grid_refs",
    "latlon_of_mgrs",
    "mgrs_of",
    "utm_of",
    "utm_zone_of",
]

#: UTM/MGRS latitudes: 80 S to 84 N inclusive (UPS beyond).
MGRS_MIN_LAT_DEG = -80.0
MGRS_MAX_LAT_DEG = 84.0

_BANDS = "CDEFGHJKLMNPQRSTUVWX"  # 8 degree bands from 80 S; X spans 72-84 N
_COLUMN_SETS = ("ABCDEFGH", "JKLMNPQR", "STUVWXYZ")  # zone 1, 2, 3 (then repeats)
_ROWS = "ABCDEFGHJKLMNPQRSTUV"  # 20 letters, 100 km each: 2000 km cycle
_MGRS_RE = re.compile(r"^(\d{1,2})([C-HJ-NP-X])([A-HJ-NP-Z])([A-HJ-NP-V])(\d*)$")


@dataclass(frozen=True)
class UtmRef:
    """A UTM coordinate on WGS84.

    Attributes
    ----------
    zone : int
        1 to 60.
    band : str
        Latitude band letter (``C`` to ``X``, no ``I``/``O``).
    north : bool
        Northern hemisphere (false northing 0) or southern (10 000 000 m).
    easting_m, northing_m : float
        Metres, false easting 500 000 m.
    """

    zone: int
    band: str
    north: bool
    easting_m: float
    northing_m: float

    @property
    def epsg(self) -> int:
        """The EPSG code of the zone's projected CRS (326zz north, 327zz south)."""
        return (32600 if self.north else 32700) + self.zone

    def __str__(self) -> str:
        """``32V 385734E 6650941N``: zone and band as GPS receivers show them, whole metres.

        The band letter, not a hemisphere letter (``N`` is also a band: 0-8 N); the
        metres are truncated as MGRS's are.
        """
        e, n = math.floor(self.easting_m), math.floor(self.northing_m)
        return f"{self.zone:02d}{self.band} {e:06d}E {n:07d}N"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``zone``, ``band``, ``hemisphere`` (N/S), metres, ``epsg``, ``text``."""
        return {
            "zone": self.zone,
            "band": self.band,
            "hemisphere": "N" if self.north else "S",
            "easting_m": self.easting_m,
            "northing_m": self.northing_m,
            "epsg": self.epsg,
            "text": str(self),
        }


def grid_refs(lat_deg: float, lon_deg: float) -> dict[str, Any]:
    """``{"mgrs": "17T NE 12345 67890", "utm": UtmRef.to_dict()}`` of a WGS84 point.

    Both are None at the poles (UPS, not supported) instead of raising: for documents
    that carry a grid reference beside every lat/lon.
    """
    try:
        u = utm_of(lat_deg, lon_deg)
    except GeodesyError:
        return {"mgrs": None, "utm": None}
    return {"mgrs": _mgrs_of_utm(u, 5, True), "utm": u.to_dict()}


def _check(lat_deg: float, lon_deg: float) -> tuple[float, float]:
    lat, lon = float(lat_deg), float(lon_deg)
    if not (math.isfinite(lat) and math.isfinite(lon)):
        raise GeodesyError(f"latitude/longitude must be finite, got {lat_deg!r}, {lon_deg!r}")
    if not -180.0 <= lon <= 180.0:
        raise GeodesyError(f"longitude {lon} is outside -180 to 180 degrees")
    if not MGRS_MIN_LAT_DEG <= lat <= MGRS_MAX_LAT_DEG:
        raise GeodesyError(
            f"latitude {lat} is outside UTM/MGRS (80 S to 84 N); polar UPS references"
            " are not supported"
        )
    return lat, (lon if lon < 180.0 else -180.0)


def _band_of(lat: float) -> str:
    return _BANDS[min(int((lat + 80.0) // 8.0), len(_BANDS) - 1)]


def utm_zone_of(lat_deg: float, lon_deg: float) -> int:
    """The UTM zone of a WGS84 point, with the Norway (32V) and Svalbard (X) exceptions.

    Raises
    ------
    GeodesyError
        Outside 80 S to 84 N (UPS) or for a non-finite or out-of-range coordinate.
    """
    lat, lon = _check(lat_deg, lon_deg)
    zone = int((lon + 180.0) // 6.0) + 1
    if 56.0 <= lat < 64.0 and 3.0 <= lon < 12.0:
        return 32
    if lat >= 72.0 and 0.0 <= lon < 42.0:
        for z, east_edge in ((31, 9.0), (33, 21.0), (35, 33.0), (37, 42.0)):
            if lon < east_edge:
                return z
    return min(zone, 60)


@lru_cache(maxsize=128)
def _to_utm(epsg: int) -> Transformer:
    return Transformer.from_crs("EPSG:4326", f"EPSG:{epsg}", always_xy=True)


@lru_cache(maxsize=128)
def _from_utm(epsg: int) -> Transformer:
    return Transformer.from_crs(f"EPSG:{epsg}", "EPSG:4326", always_xy=True)


def utm_of(lat_deg: float, lon_deg: float) -> UtmRef:
    """The UTM coordinate of a WGS84 point, in the zone :func:`utm_zone_of` gives.

    Parameters
    ----------
    lat_deg, lon_deg : float
        WGS84 latitude (80 S to 84 N) and longitude (degrees).

    Raises
    ------
    GeodesyError
        Outside UTM's latitudes (the poles are UPS) or for a bad coordinate.
    """
    lat, lon = _check(lat_deg, lon_deg)
    zone = utm_zone_of(lat, lon)
    north = lat >= 0.0
    e, n = _to_utm((32600 if north else 32700) + zone).transform(lon, lat, errcheck=True)
    return UtmRef(zone, _band_of(lat), north, float(e), float(n))


def mgrs_of(lat_deg: float, lon_deg: float, precision: int = 5, *, spaced: bool = True) -> str:
    """The MGRS reference of a WGS84 point.

    Parameters
    ----------
    lat_deg, lon_deg : float
        WGS84 latitude (80 S to 84 N) and longitude (degrees).
    precision : int
        Digits per coordinate, 0 (100 km square) to 5 (1 m).
    spaced : bool
        ``32V KM 76979 58157`` (the form people read) or ``32VKM7697958157``.

    Returns
    -------
    str
        The reference of the square of ``10**(5 - precision)`` m that holds the point
        (coordinates truncated, never rounded into the next square).

    Raises
    ------
    GeodesyError
        Outside 80 S to 84 N (UPS is not supported) or for a bad coordinate or precision.
    """
    if not isinstance(precision, int) or not 0 <= precision <= 5:
        raise GeodesyError(f"MGRS precision must be an integer from 0 to 5, got {precision!r}")
    return _mgrs_of_utm(utm_of(lat_deg, lon_deg), precision, spaced)


def _mgrs_of_utm(u: UtmRef, precision: int, spaced: bool) -> str:
    """The MGRS lettering of a UTM coordinate (``precision`` checked by the caller)."""
    # Truncate at the metre first (a hair below an integer must not round up).
    e_1m, n_1m = math.floor(u.easting_m), math.floor(u.northing_m)
    col = _COLUMN_SETS[(u.zone - 1) % 3][e_1m // 100_000 - 1]
    row_offset = 5 if u.zone % 2 == 0 else 0
    row = _ROWS[(n_1m // 100_000 + row_offset) % 20]
    scale = 10 ** (5 - precision)
    e_d = f"{(e_1m % 100_000) // scale:0{precision}d}" if precision else ""
    n_d = f"{(n_1m % 100_000) // scale:0{precision}d}" if precision else ""
    head = f"{u.zone:02d}{u.band}"
    if not spaced:
        return f"{head}{col}{row}{e_d}{n_d}"
    return " ".join(part for part in (head, col + row, e_d, n_d) if part)


def latlon_of_mgrs(ref: str, *, centre: bool = True) -> tuple[float, float]:
    """The WGS84 ``(lat_deg, lon_deg)`` of an MGRS reference (spaces ignored).

    Parameters
    ----------
    ref : str
        ``32V KM 76979 58157``, ``32VKM7697958157``, or any precision (an even number of
        digits, 0 to 10).
    centre : bool
        The centre of the referenced square (default) or its south-west corner.

    Raises
    ------
    GeodesyError
        For a malformed reference, a square letter that does not exist in its zone, or a
        square that does not lie in its latitude band.
    """
    text = re.sub(r"\s+", "", str(ref)).upper()
    m = _MGRS_RE.match(text)
    if m is None:
        raise GeodesyError(
            f"not an MGRS reference: {ref!r} (expected zone, band, two square letters and"
            " digits, e.g. 32V KM 76979 58157; polar UPS references are not supported)"
        )
    zone, band, col, row, digits = int(m[1]), m[2], m[3], m[4], m[5]
    if not 1 <= zone <= 60 or len(digits) % 2 or len(digits) > 10:
        raise GeodesyError(f"not an MGRS reference: {ref!r} (zone 1-60, 0 to 5 digit pairs)")
    cols = _COLUMN_SETS[(zone - 1) % 3]
    if col not in cols:
        raise GeodesyError(f"MGRS {ref!r}: column letter {col} does not exist in zone {zone}")
    precision = len(digits) // 2
    scale = 10 ** (5 - precision)
    e_in = int(digits[:precision]) * scale if precision else 0
    n_in = int(digits[precision:]) * scale if precision else 0
    half = scale / 2.0 if centre else 0.0
    easting = (cols.index(col) + 1) * 100_000 + e_in + half
    row_offset = 5 if zone % 2 == 0 else 0
    n_mod = ((_ROWS.index(row) - row_offset) % 20) * 100_000 + n_in + half
    b = _BANDS.index(band)
    south_lat = -80.0 + 8.0 * b
    north_lat = 84.0 if band == "X" else south_lat + 8.0
    north = band >= "N"
    epsg = (32600 if north else 32700) + zone
    cm = -183.0 + 6.0 * zone
    # The band's lowest northing: a parallel's northing is lowest on the central meridian
    # in the north and at the zone edges in the south; 3.5 degrees off covers 32V and X.
    lows = [_to_utm(epsg).transform(cm + dl, south_lat)[1] for dl in (-3.5, 0.0, 3.5)]
    low = min(lows) - 1000.0
    northing = n_mod + 2_000_000 * math.ceil((low - n_mod) / 2_000_000)
    lon, lat = _from_utm(epsg).transform(easting, northing)
    tol = 0.01  # degrees: a square's corner may sit a hair over its band's edge
    if not (south_lat - tol <= lat <= north_lat + tol) or not math.isfinite(lon):
        raise GeodesyError(f"MGRS {ref!r}: square {col}{row} does not lie in band {band}")
    return float(lat), float(lon)
