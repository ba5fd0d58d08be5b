"""The site frame: a Local Vertical Coordinate System on the WGS84 ellipsoid.

:class:`LocalFrame` is the "ENU" frame of ``docs/conventions.md``: X east, Y true (geodetic)
north, Z up along the ellipsoid normal at the anchor, metres, origin at the anchor point
(WGS84 latitude, longitude, ellipsoidal height). Conversions are exact: geodetic
coordinates go to ECEF through PROJ (EPSG:4979 -> EPSG:4978) and ECEF is rotated into the
tangent frame, as GeographicLib's ``LocalCartesian`` does; there is no flat-earth
approximation anywhere.

Accuracy (measured with this module's tests): ENU agrees with an independent closed-form
numpy twin and with published reference values to well under 1 mm. ENU -> geodetic -> ENU
round trips to ~1e-9 m near the surface: the geocentric -> geodetic latitude comes from
PROJ (Bowring's method, one step; its error grows as h^2: ~2e-7 m of position at 5 km
above the ellipsoid, ~9e-7 m at 10 km) and the height is recomputed from that latitude
with the exact normal-projection formula (good to ~1e-8 m at any latitude, poles included).

Datums: heights leaving or entering through the ``*_crs`` helpers are ellipsoidal unless a
geoid undulation ``N`` is given (orthometric ``H`` becomes ``h = H + N``). Horizontal datum
shifts between the source CRS's datum and WGS84 are whatever PROJ selects as best available
offline (NAD83 -> WGS84 is then the null transformation, EPSG:1188; metre-level realisation
differences are not modelled).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Any

import numpy as np
from pyproj import CRS, Proj, Transformer
from pyproj.exceptions import CRSError as _PyprojCRSError

from ..errors import CrsError, GeodesyError

__all__ = [
    "WGS84_A_M",
    "WGS84_F",
    "LocalFrame",
    "as_crs",
    "cached_transformer",
    "horizontal_crs",
    "meridian_convergence_deg",
    "scale_factor",
    "z_unit_m_of",
]

WGS84_A_M = 6378137.0
"""WGS84 semi-major axis (m)."""
WGS84_F = 1.0 / 298.257223563
"""WGS84 flattening."""
_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared

_GEOG3D = "EPSG:4979"  # WGS84 geographic 3-D: lat, lon, ellipsoidal height
_ECEF = "EPSG:4978"  # WGS84 geocentric
_GEOG2D = "EPSG:4326"  # WGS84 geographic 2-D


# --------------------------------------------------------------------------- CRS helpers


def as_crs(crs: Any) -> CRS:
    """Parse anything pyproj accepts (``CRS``, ``"EPSG:32617"``, WKT, an EPSG code).

    Raises
    ------
    CrsError
        If ``crs`` is None or not understood by PROJ.
    """
    if crs is None:
        raise CrsError("no CRS given")
    if isinstance(crs, CRS):
        return crs
    # rasterio's CRS is not a pyproj CRS; its WKT is the lossless common ground.
    if hasattr(crs, "to_wkt") and not isinstance(crs, str):
        crs = crs.to_wkt()
    try:
        return CRS.from_user_input(crs)
    except _PyprojCRSError as exc:
        raise CrsError(f"unknown CRS {str(crs)[:80]!r}: {str(exc).splitlines()[0]}") from exc


def horizontal_crs(crs: Any) -> CRS:
    """Return the 2-D (horizontal) part of ``crs``: a projected or geographic CRS.

    Compound CRSs give their horizontal component; 3-D geographic/projected CRSs their
    2-D form. Heights are handled apart from PROJ (see :meth:`LocalFrame.to_enu_from_crs`).

    Raises
    ------
    CrsError
        For geocentric, engineering or purely vertical CRSs.
    """
    c = as_crs(crs)
    if c.is_compound:
        c = c.sub_crs_list[0]
    if c.is_geocentric:
        raise CrsError(
            f"geocentric CRS {c.name!r} is not supported here; use LocalFrame.ecef_to_enu"
        )
    if not (c.is_projected or c.is_geographic):
        raise CrsError(f"CRS {c.name!r} is neither projected nor geographic")
    if len(c.axis_info) == 3:
        c = c.to_2d()
    return c


def z_unit_m_of(crs: Any) -> float:
    """Default size (m) of one unit of z for coordinates in ``crs``.

    The vertical axis's unit when the CRS has one (compound or 3-D CRS); otherwise the
    horizontal linear unit of a projected CRS (LAS/DEM practice: a state-plane ftUS
    file carries heights in ftUS); otherwise (geographic 2-D) metres.
    """
    c = as_crs(crs)
    for axis in c.axis_info:
        if axis.direction == "up":
            return float(axis.unit_conversion_factor)
    h = horizontal_crs(c)
    if h.is_projected:
        return float(h.axis_info[0].unit_conversion_factor)
    return 1.0


@lru_cache(maxsize=64)
def cached_transformer(src: str, dst: str) -> Transformer:
    """Return a cached ``always_xy`` PROJ transformer between two CRSs.

    Parameters
    ----------
    src, dst : str
        ``"EPSG:nnnn"`` codes or WKT strings (hashable keys for the cache).
    """
    # pyproj >= 3.1 Transformers are thread-safe (one PROJ object per thread), so one
    # cached instance may serve every thread.
    return Transformer.from_crs(src, dst, always_xy=True)


def _crs_key(c: CRS) -> str:
    return c.to_wkt()


@lru_cache(maxsize=32)
def _proj(wkt: str) -> Proj:
    return Proj(CRS.from_wkt(wkt))


def _factors(crs: Any, lat_deg: Any, lon_deg: Any):
    h = horizontal_crs(crs)
    lat, lon = _check_lat_lon(lat_deg, lon_deg)
    shape = np.broadcast_shapes(lat.shape, lon.shape)
    lat_b = np.broadcast_to(lat, shape).ravel()
    lon_b = np.broadcast_to(lon, shape).ravel()
    factors = _proj(_crs_key(h)).get_factors(lon_b, lat_b) if h.is_projected else None
    return h, shape, factors


def meridian_convergence_deg(crs: Any, lat_deg: Any, lon_deg: Any) -> np.ndarray | float:
    """Meridian convergence of a projected CRS at WGS84 points (degrees).

    The angle from true (geodetic) north to grid north, positive clockwise, so that
    ``grid_azimuth = true_azimuth - gamma``. In UTM it is about
    ``(lon - lon_0) * sin(lat)``: positive east of the central meridian in the northern
    hemisphere (+0.89 deg at Bushy Run, PA, in UTM 17N). Geographic CRSs give 0.

    The point is taken as lying in the CRS's own geodetic datum (a datum shift of a few
    metres changes gamma by far less than 1e-6 deg). Broadcasts ``lat_deg``/``lon_deg``.
    """
    h, shape, f = _factors(crs, lat_deg, lon_deg)
    gamma = np.zeros(shape) if f is None else np.asarray(f.meridian_convergence).reshape(shape)
    return gamma if gamma.shape else float(gamma)


def scale_factor(crs: Any, lat_deg: Any, lon_deg: Any) -> np.ndarray | float:
    """Point scale factor ``k`` of a projected CRS on its ellipsoid (dimensionless).

    Grid distance / ellipsoidal distance along a parallel (PROJ ``parallel_scale``; for the
    conformal projections used for DEMs, UTM and state planes, it is the same in every
    direction). Units do not enter: a ftUS grid has ``k`` near 1 too. At height ``h`` a
    ground distance is further scaled by ``R / (R + h)``; :class:`LocalFrame` needs
    neither factor because it converts exactly.

    Raises
    ------
    CrsError
        For geographic CRSs (degrees have no scale factor).
    """
    h, shape, f = _factors(crs, lat_deg, lon_deg)
    if f is None:
        raise CrsError(f"CRS {h.name!r} is geographic; a scale factor needs a projected CRS")
    k = np.asarray(f.parallel_scale).reshape(shape)
    return k if k.shape else float(k)


# --------------------------------------------------------------------------- validation


def _finite(name: str, value: Any) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeodesyError(f"{name} must be numeric") from exc
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.isfinite(arr)].ravel()[0] if arr.ndim else arr
        raise GeodesyError(f"{name} must be finite; got {float(bad)}")
    return arr


def _check_lat_lon(lat_deg: Any, lon_deg: Any) -> tuple[np.ndarray, np.ndarray]:
    lat = _finite("latitude (deg)", lat_deg)
    lon = _finite("longitude (deg)", lon_deg)
    out = np.abs(lat) > 90.0
    if np.any(out):
        bad = lat[out].ravel()[0] if lat.ndim else lat
        raise GeodesyError(f"latitude must be within [-90, 90] degrees; got {float(bad)}")
    return lat, lon


def _broadcast(*arrays: np.ndarray) -> tuple[tuple[int, ...], list[np.ndarray]]:
    try:
        shape = np.broadcast_shapes(*(a.shape for a in arrays))
    except ValueError as exc:
        raise GeodesyError(
            f"coordinate arrays do not broadcast: {', '.join(str(a.shape) for a in arrays)}"
        ) from exc
    return shape, [np.broadcast_to(a, shape).ravel() for a in arrays]


def _same_length_enu(e: Any, n: Any, u: Any) -> np.ndarray | None:
    """``np.stack([e, n, u])`` when all three are finite 1-D float64 arrays of one length.

    The usual call (columns of an ``(n, 3)`` array) in one copy and one finiteness check,
    instead of three conversions, three checks and three broadcasts; the same values.
    None for anything else: the general path converts, broadcasts and names the problem.
    """
    if not (
        type(e) is np.ndarray
        and type(n) is np.ndarray
        and type(u) is np.ndarray
        and e.dtype == n.dtype == u.dtype == np.float64
        and e.ndim == n.ndim == u.ndim == 1
        and len(e) == len(n) == len(u)
    ):
        return None
    enu = np.empty((3, len(e)))
    enu[0], enu[1], enu[2] = e, n, u
    return enu if np.isfinite(enu).all() else None


def _out(shape: tuple[int, ...], *arrays: np.ndarray) -> tuple[Any, ...]:
    # Scalars in, numpy float64 scalars out; arrays keep the broadcast shape.
    if shape == ():
        return tuple(np.float64(a.reshape(-1)[0]) for a in arrays)
    return tuple(np.asarray(a, dtype=np.float64).reshape(shape) for a in arrays)


# --------------------------------------------------------------------------- the frame


@dataclass(frozen=True)
class LocalFrame:
    """Local Vertical Coordinate System anchored at a WGS84 point.

    Parameters
    ----------
    lat_deg, lon_deg : float
        Geodetic WGS84 latitude in [-90, 90] and longitude (any finite value) of the
        origin, degrees.
    h_m : float
        Height of the origin above the WGS84 ellipsoid (m).

    Notes
    -----
    ``e, n, u`` are metres along east, true north and the ellipsoid normal at the origin.
    At the poles east/north are those of the meridian ``lon_deg``.
    """

    lat_deg: float
    lon_deg: float
    h_m: float

    def __post_init__(self) -> None:
        lat, lon = _check_lat_lon(self.lat_deg, self.lon_deg)
        h = _finite("anchor height h_m", self.h_m)
        if lat.ndim or lon.ndim or h.ndim:
            raise GeodesyError("the frame anchor must be three scalars")
        object.__setattr__(self, "lat_deg", float(lat))
        object.__setattr__(self, "lon_deg", float(lon))
        object.__setattr__(self, "h_m", float(h))

    # cached_property writes the instance __dict__ directly, so it works on frozen classes.
    @cached_property
    def R_enu_ecef(self) -> np.ndarray:  # noqa: N802  (frame names, per conventions)
        """Rotation ``(3, 3)`` taking ECEF vectors to ENU: rows are east, north, up."""
        phi, lam = np.radians(self.lat_deg), np.radians(self.lon_deg)
        sp, cp, sl, cl = np.sin(phi), np.cos(phi), np.sin(lam), np.cos(lam)
        return np.array([[-sl, cl, 0.0], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]])

    @cached_property
    def origin_ecef(self) -> np.ndarray:
        """ECEF position ``(3,)`` of the origin (m), through the same PROJ conversion."""
        x, y, z = cached_transformer(_GEOG3D, _ECEF).transform(self.lon_deg, self.lat_deg, self.h_m)
        return np.array([x, y, z], dtype=np.float64)

    # ---- ECEF <-> ENU (pure rotation + translation)

    def ecef_to_enu(self, x_m: Any, y_m: Any, z_m: Any) -> tuple[Any, Any, Any]:
        """WGS84 ECEF (m) to local ``(e, n, u)`` (m). Broadcasts; scalars give scalars."""
        shape, (x, y, z) = _broadcast(_finite("x", x_m), _finite("y", y_m), _finite("z", z_m))
        d = np.stack([x, y, z]) - self.origin_ecef[:, None]
        enu = self.R_enu_ecef @ d
        return _out(shape, enu[0], enu[1], enu[2])

    def enu_to_ecef(self, e_m: Any, n_m: Any, u_m: Any) -> tuple[Any, Any, Any]:
        """Local ``(e, n, u)`` (m) to WGS84 ECEF (m). Broadcasts; scalars give scalars."""
        shape, (e, n, u) = _broadcast(_finite("e", e_m), _finite("n", n_m), _finite("u", u_m))
        xyz = self.R_enu_ecef.T @ np.stack([e, n, u]) + self.origin_ecef[:, None]
        return _out(shape, xyz[0], xyz[1], xyz[2])

    # ---- geodetic <-> ENU

    def to_enu(self, lat_deg: Any, lon_deg: Any, h_m: Any) -> tuple[Any, Any, Any]:
        """WGS84 geodetic (deg, deg, m ellipsoidal) to local ``(e, n, u)`` (m).

        Broadcasts its arguments; scalars give scalars.

        Raises
        ------
        GeodesyError
            On a latitude outside [-90, 90] or any non-finite value.
        """
        lat, lon = _check_lat_lon(lat_deg, lon_deg)
        shape, (lat, lon, h) = _broadcast(lat, lon, _finite("height h_m", h_m))
        x, y, z = cached_transformer(_GEOG3D, _ECEF).transform(lon, lat, h)
        d = np.stack([np.asarray(x), np.asarray(y), np.asarray(z)]) - self.origin_ecef[:, None]
        enu = self.R_enu_ecef @ d
        return _out(shape, enu[0], enu[1], enu[2])

    def to_geodetic(self, e_m: Any, n_m: Any, u_m: Any) -> tuple[Any, Any, Any]:
        """Local ``(e, n, u)`` (m) to WGS84 ``(lat_deg, lon_deg, h_m)`` (h ellipsoidal).

        Longitudes come back in [-180, 180]; on the polar axis the longitude is 0.
        Broadcasts its arguments; scalars give scalars.
        """
        enu = _same_length_enu(e_m, n_m, u_m)
        if enu is None:  # the general path: broadcasting, and the checks that name a bad value
            shape, (e, n, u) = _broadcast(_finite("e", e_m), _finite("n", n_m), _finite("u", u_m))
            enu = np.stack([e, n, u])
        else:
            shape = enu.shape[1:]
        xyz = self.R_enu_ecef.T @ enu + self.origin_ecef[:, None]
        lon, lat, _ = cached_transformer(_ECEF, _GEOG3D).transform(xyz[0], xyz[1], xyz[2])
        lat = np.asarray(lat)
        # PROJ's height is good to ~3e-7 m near the surface but switches formula poleward
        # of 89.99994 deg (errors of a few 1e-6 m there). This projection of the point on
        # the normal is exact for PROJ's latitude at every latitude and, being stationary
        # in latitude, insensitive to its small error: h is then good to ~1e-8 m anywhere.
        phi = np.radians(lat)
        sphi, cphi = np.sin(phi), np.cos(phi)
        h = (
            np.hypot(xyz[0], xyz[1]) * cphi
            + xyz[2] * sphi
            - WGS84_A_M * np.sqrt(1.0 - _E2 * sphi * sphi)
        )
        return _out(shape, lat, np.asarray(lon), h)

    # ---- any CRS <-> ENU

    def to_enu_from_crs(
        self,
        x: Any,
        y: Any,
        z: Any,
        crs: Any,
        *,
        geoid_undulation_m: float = 0.0,
        z_unit_m: float | None = None,
    ) -> tuple[Any, Any, Any]:
        """Coordinates in ``crs`` to local ``(e, n, u)`` (m).

        Parameters
        ----------
        x, y : array_like
            Easting/northing in the CRS's units (projected), or lon/lat in degrees
            (geographic; x = longitude whatever the CRS's axis order).
        z : array_like
            Heights in units of ``z_unit_m``: ellipsoidal when ``geoid_undulation_m`` is 0,
            else orthometric, converted as ``h = z * z_unit_m + N``.
        crs : CRS-like
            Projected, geographic or compound CRS (see :func:`horizontal_crs`).
        geoid_undulation_m : float
            Geoid undulation ``N`` (m) at the site.
        z_unit_m : float, optional
            Metres per z unit; default :func:`z_unit_m_of` ``(crs)``.
        """
        hcrs = horizontal_crs(crs)
        k = z_unit_m_of(crs) if z_unit_m is None else _positive("z_unit_m", z_unit_m)
        n_geoid = float(_finite("geoid_undulation_m", geoid_undulation_m))
        shape, (xa, ya, za) = _broadcast(_finite("x", x), _finite("y", y), _finite("z", z))
        lon, lat = cached_transformer(_crs_key(hcrs), _GEOG2D).transform(xa, ya)
        lon, lat = np.asarray(lon), np.asarray(lat)
        if not (np.all(np.isfinite(lon)) and np.all(np.isfinite(lat))):
            raise CrsError(f"some points cannot be converted from {hcrs.name!r} to WGS84")
        e, n, u = self.to_enu(lat, lon, za * k + n_geoid)
        return _out(shape, np.asarray(e), np.asarray(n), np.asarray(u))

    def from_enu_to_crs(
        self,
        e_m: Any,
        n_m: Any,
        u_m: Any,
        crs: Any,
        *,
        geoid_undulation_m: float = 0.0,
        z_unit_m: float | None = None,
    ) -> tuple[Any, Any, Any]:
        """Local ``(e, n, u)`` (m) to ``(x, y, z)`` in ``crs``; inverse of :meth:`to_enu_from_crs`.

        ``z = (h - N) / z_unit_m``; geographic CRSs give x = longitude, y = latitude.
        """
        hcrs = horizontal_crs(crs)
        k = z_unit_m_of(crs) if z_unit_m is None else _positive("z_unit_m", z_unit_m)
        n_geoid = float(_finite("geoid_undulation_m", geoid_undulation_m))
        lat, lon, h = self.to_geodetic(e_m, n_m, u_m)
        lat, lon, h = np.asarray(lat), np.asarray(lon), np.asarray(h)
        x, y = cached_transformer(_GEOG2D, _crs_key(hcrs)).transform(lon.ravel(), lat.ravel())
        x = np.asarray(x).reshape(lat.shape)
        y = np.asarray(y).reshape(lat.shape)
        return _out(lat.shape, x, y, (h - n_geoid) / k)

    # ---- serialisation

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict; heights are ellipsoidal (the ``crs`` entry says so)."""
        return {"lat_deg": self.lat_deg, "lon_deg": self.lon_deg, "h_m": self.h_m, "crs": _GEOG3D}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> LocalFrame:
        """Inverse of :meth:`to_dict`.

        Raises
        ------
        GeodesyError
            On missing keys, non-numeric values or a ``crs`` other than EPSG:4979.
        """
        if not isinstance(d, Mapping):
            raise GeodesyError("a local frame must be given as a mapping")
        missing = [k for k in ("lat_deg", "lon_deg", "h_m") if k not in d]
        if missing:
            raise GeodesyError(f"local frame is missing {', '.join(missing)}")
        crs = d.get("crs", _GEOG3D)
        if str(crs).upper() != _GEOG3D:
            raise GeodesyError(
                f"local frame anchor must be in {_GEOG3D} (WGS84, ellipsoidal height); got {crs!r}"
            )
        vals = []
        for key in ("lat_deg", "lon_deg", "h_m"):
            v = d[key]
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise GeodesyError(f"local frame {key} must be a number; got {v!r}")
            vals.append(float(v))
        return cls(*vals)


def _positive(name: str, value: float) -> float:
    v = float(_finite(name, value))
    if v <= 0:
        raise CrsError(f"{name} must be positive; got {v}")
    return v
