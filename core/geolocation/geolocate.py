"""Pixel -> viewing ray -> terrain hits, with the paper's selection rules.

The geolocation point of a target is the bottom-centre of its bounding box (Collins et al.
1998). Its viewing ray is intersected with the DEM surface; every crossing is reported,
nearest first, and a rule picks the answer:

``first``
    The nearest crossing (can land in a tree crown in front of the target).
``last``
    The farthest crossing (the paper's heuristic against foliage occlusion).
``all``
    Every crossing.
``road``
    The crossing of the ray's ground track with the road network minimising
    ``|DEM elevation - ray height|`` (the paper's domain-knowledge rule for vehicles);
    "no hit" when the ray meets no road within the cut-off.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np

from ..camera.pinhole import Camera, distortion_jacobian
from ..errors import CameraError
from ..raycast.cast import RayStatus, cast_rays
from ..raycast.tiled_cast import DEFAULT_MEMORY_BUDGET, TiledRayCaster
from ..terrain.dem import Dem
from ..terrain.tiled_dem import TiledDem
from .roads import RoadNetwork
from .uncertainty import hit_covariances

__all__ = [
    "RULES",
    "GroundHit",
    "Geolocation",
    "Geolocator",
    "HitBatch",
    "Rule",
]

Rule = Literal["first", "last", "all", "road"]
RULES: tuple[str, ...] = ("first", "last", "all", "road")


@dataclass(frozen=True)
class GroundHit:
    """One point where a viewing ray meets the ground.

    Attributes
    ----------
    p_enu : ndarray, shape (3,)
        Site frame (m); z is local-frame up.
    lat_deg, lon_deg, h_m : float
        WGS84 geodetic position; ``h_m`` is height above the WGS84 ellipsoid.
    range_m : float
        Distance from the camera centre along the ray (m).
    sigma_m : float
        1-sigma horizontal uncertainty along the worst direction (m), from pixel noise
        and DEM variance.
    cov_en_m2 : ndarray, shape (2, 2)
        Horizontal covariance (east, north) in m^2.
    source : str
        ``"terrain"`` for a ray-surface crossing, ``"road"`` for a road-rule point.
    """

    p_enu: np.ndarray
    lat_deg: float
    lon_deg: float
    h_m: float
    range_m: float
    sigma_m: float
    cov_en_m2: np.ndarray
    source: str = "terrain"

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {
            "e_m": float(self.p_enu[0]),
            "n_m": float(self.p_enu[1]),
            "u_m": float(self.p_enu[2]),
            "lat_deg": self.lat_deg,
            "lon_deg": self.lon_deg,
            "h_m": self.h_m,
            "range_m": self.range_m,
            "sigma_m": self.sigma_m,
            "source": self.source,
        }


@dataclass(frozen=True)
class Geolocation:
    """The answer for one pixel.

    Attributes
    ----------
    u, v : float
        The pixel (column, row; (0, 0) is the centre of the top-left pixel).
    origin_enu, direction_enu : ndarray, shape (3,)
        The viewing ray (unit direction).
    status : str
        ``hit``, ``miss``, ``below_ground``, ``outside``, ``upward`` or ``no_road``.
    hits : tuple of GroundHit
        Every terrain crossing, nearest first.
    road : GroundHit or None
        The road-rule point, when roads were given and the ray crosses one.
    rule : str
        The rule used for ``selected``.
    selected : tuple of GroundHit
        The hits the rule picks (all of them for ``all``; at most one otherwise).
    crossed_nodata : bool
        The ray passed over a DEM hole, so a crossing may be missing.
    """

    u: float
    v: float
    origin_enu: np.ndarray
    direction_enu: np.ndarray
    status: str
    hits: tuple[GroundHit, ...]
    road: GroundHit | None
    rule: str
    selected: tuple[GroundHit, ...]
    crossed_nodata: bool

    @property
    def best(self) -> GroundHit | None:
        """The single chosen hit (the first of ``selected``), if any."""
        return self.selected[0] if self.selected else None


@dataclass(frozen=True, eq=False)
class HitBatch:
    """Terrain crossings and road-rule points of a batch of rays, in CSR layout.

    Attributes
    ----------
    origins_enu, directions_enu : ndarray, shape (n, 3)
        The rays (site frame, m; unit directions).
    status : ndarray, int8, shape (n,)
        :class:`~demtrack.core.raycast.cast.RayStatus` per ray.
    crossed_nodata : ndarray, bool, shape (n,)
        The ray passed over a DEM hole, so a crossing may be missing.
    offsets : ndarray, int64, shape (n + 1,)
        Hits of ray ``i`` are rows ``offsets[i]:offsets[i+1]`` of the per-hit arrays.
    points_enu : ndarray, shape (m, 3)
        Every terrain crossing, nearest first per ray (site frame, m).
    range_m, sigma_m : ndarray, shape (m,)
        Range along the ray (m) and 1-sigma worst-direction horizontal error (m).
    cov_en_m2 : ndarray, shape (m, 2, 2)
        Horizontal (east, north) covariance (m^2).
    road_enu : ndarray, shape (n, 3)
        The road rule's point per ray; NaN rows where none.
    road_range_m, road_sigma_m : ndarray, shape (n,)
        Its range (m) and sigma (m); NaN where none.
    road_cov_en_m2 : ndarray, shape (n, 2, 2)
        Its covariance (m^2); NaN where none.

    The sigmas are worked out from the covariances on first use (the fix builder, the
    batch path, needs none of them).
    """

    origins_enu: np.ndarray
    directions_enu: np.ndarray
    status: np.ndarray
    crossed_nodata: np.ndarray
    offsets: np.ndarray
    points_enu: np.ndarray
    range_m: np.ndarray
    cov_en_m2: np.ndarray
    road_enu: np.ndarray
    road_range_m: np.ndarray
    road_cov_en_m2: np.ndarray

    # cached_property writes the instance __dict__ directly, so it works on frozen classes.
    @cached_property
    def sigma_m(self) -> np.ndarray:
        """1-sigma worst-direction horizontal error of each terrain hit (m), shape (m,)."""
        return _worst_sigma(self.cov_en_m2)

    @cached_property
    def road_sigma_m(self) -> np.ndarray:
        """The road-rule point's sigma (m) per ray, shape (n,); NaN where none."""
        out = np.full(len(self.road_range_m), np.nan)
        rays = np.flatnonzero(self.has_road)
        out[rays] = _worst_sigma(self.road_cov_en_m2[rays])
        return out

    @property
    def n_rays(self) -> int:
        """Number of rays ``n``."""
        return int(len(self.status))

    @property
    def counts(self) -> np.ndarray:
        """Number of terrain hits per ray, int64 shape (n,)."""
        return np.diff(self.offsets)

    @property
    def has_road(self) -> np.ndarray:
        """Boolean mask of rays with a road-rule point, shape (n,)."""
        return np.isfinite(self.road_range_m)


class Geolocator:
    """Geolocates pixels of cameras against a DEM, one camera or a batch of them at once.

    Parameters
    ----------
    dem : Dem or TiledDem
        An in-memory DEM, or a tiled one larger than memory
        (``core.terrain.tiled_dem``), cast with a
        :class:`~demtrack.core.raycast.tiled_cast.TiledRayCaster`: the same hits.
    frame : LocalFrame
        Anchor of the site frame, for WGS84 output.
    roads : RoadNetwork, optional
        Enables the ``road`` rule.
    pixel_sigma_px : float
        1-sigma error of the picked pixel (box-bottom jitter), for uncertainty.
    max_range_m : float
        Rays are followed this far.
    road_cutoff_m : float
        The road rule considers crossings out to this range.
    road_max_gap_m : float
        The road rule gives no answer when the ray passes more than this far above or
        below the road at its best crossing (m).
    memory_budget : int
        Bytes of decoded blocks a tiled DEM's caster may hold (unused for a ``Dem``).
    """

    def __init__(
        self,
        dem: Dem | TiledDem,
        frame,
        roads: RoadNetwork | None = None,
        *,
        pixel_sigma_px: float = 1.0,
        max_range_m: float = 5000.0,
        road_cutoff_m: float = 1000.0,
        road_max_gap_m: float = 3.0,
        memory_budget: int = DEFAULT_MEMORY_BUDGET,
    ) -> None:
        for name, value in (
            ("pixel_sigma_px", pixel_sigma_px),
            ("max_range_m", max_range_m),
            ("road_cutoff_m", road_cutoff_m),
            ("road_max_gap_m", road_max_gap_m),
        ):
            if not float(value) > 0:
                raise CameraError(f"{name} must be positive, got {value!r}")
        self.dem = dem
        # A tiled DEM casts through its own caster (an LRU of blocks); a Dem shares its
        # cached RayCaster through cast_rays.
        self._tiled = TiledRayCaster(dem, memory_budget) if isinstance(dem, TiledDem) else None
        self.frame = frame
        self.roads = roads
        self.pixel_sigma_px = float(pixel_sigma_px)
        self.max_range_m = float(max_range_m)
        self.road_cutoff_m = float(road_cutoff_m)
        self.road_max_gap_m = float(road_max_gap_m)

    def geolocate(
        self,
        camera,
        u: Sequence[float] | np.ndarray,
        v: Sequence[float] | np.ndarray,
        rule: str = "first",
    ) -> list[Geolocation]:
        """Geolocate pixels of ``camera``; one :class:`Geolocation` per pixel.

        Raises
        ------
        CameraError
            If a pixel lies outside the image or the rule is unknown.
        """
        return self.geolocate_many([(camera, u, v)], rule)[0]

    def geolocate_many(
        self, views: Sequence[tuple[Any, Any, Any]], rule: str = "first"
    ) -> list[list[Geolocation]]:
        """Geolocate pixels of several cameras in one batch.

        Parameters
        ----------
        views : sequence of (camera, u, v)
            Each camera with its pixel columns and rows (array_like, same length).
        rule : str
            One of :data:`RULES`.

        Returns
        -------
        list of list of Geolocation
            One list per view, one :class:`Geolocation` per pixel, in order; the same
            answers as :meth:`geolocate` per camera.

        Raises
        ------
        CameraError
            If a pixel lies outside its image or the rule is unknown.
        """
        if rule not in RULES:
            raise CameraError(f"unknown rule {rule!r}; choose one of {', '.join(RULES)}")
        pixels = [_pixels(camera, u, v) for camera, u, v in views]
        cameras = [view[0] for view in views]
        batch = self.locate_pixels(
            [(cam, u, v) for cam, (u, v) in zip(cameras, pixels, strict=True)]
        )
        hits, roads = self._ground_hit_objects(batch)
        out: list[list[Geolocation]] = []
        i = 0
        for u_arr, v_arr in pixels:
            locs = []
            for k in range(len(u_arr)):
                lo, hi = int(batch.offsets[i]), int(batch.offsets[i + 1])
                ray_hits = tuple(hits[lo:hi])
                road = roads[i]
                status = RayStatus(int(batch.status[i])).name.lower()
                if rule == "road" and road is None:
                    status = "no_road"
                locs.append(
                    Geolocation(
                        float(u_arr[k]),
                        float(v_arr[k]),
                        batch.origins_enu[i],
                        batch.directions_enu[i],
                        status,
                        ray_hits,
                        road,
                        rule,
                        self._select(ray_hits, road, rule),
                        bool(batch.crossed_nodata[i]),
                    )
                )
                i += 1
            out.append(locs)
        return out

    def locate_pixels(self, views: Sequence[tuple[Any, Any, Any]]) -> HitBatch:
        """Every terrain crossing and road-rule point of many cameras' pixels, as arrays.

        The bulk form of :meth:`geolocate` (no rule, no geodetic output): one ray cast
        for all pixels of all cameras, vectorised uncertainty and road rule.

        Parameters
        ----------
        views : sequence of (camera, u, v)
            Each camera with its pixel columns and rows; rays are numbered in this order.

        Returns
        -------
        HitBatch

        Raises
        ------
        CameraError
            If a pixel lies outside its image.
        """
        return self.locate_ray_parts(self.pixel_rays(views))

    def pixel_rays(
        self, views: Sequence[tuple[Any, Any, Any]]
    ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """Each view's rays and pixel perturbations, the parts :meth:`locate_ray_parts` takes.

        Parameters
        ----------
        views : sequence of (camera, u, v)
            As :meth:`locate_pixels`.

        Returns
        -------
        list of (origins, directions, perturb_axes, perturb_sigmas)
            One per view, shapes as :meth:`locate_rays` takes them.
        """
        rays = []
        for camera, u, v in views:
            u_arr, v_arr = _pixels(camera, u, v)
            if type(camera) is Camera:
                # One undistortion per pixel for the ray and its perturbations.
                rays.append(_rays_and_perturbations(camera, u_arr, v_arr, self.pixel_sigma_px))
                continue
            origins, dirs = camera.pixel_to_ray(u_arr, v_arr)
            axes, sig = _pixel_perturbations(camera, u_arr, v_arr, self.pixel_sigma_px)
            rays.append((origins, dirs, axes, sig))
        return rays

    def locate_ray_parts(
        self, parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    ) -> HitBatch:
        """:meth:`locate_rays` on several groups of rays at once, numbered in their order.

        Each part is ``(origins, directions, perturb_axes, perturb_sigmas)`` (what
        :meth:`pixel_rays` and
        :func:`~demtrack.core.geolocation.posed_rays.posed_view_rays` make): one ray cast
        for all of them.
        """
        rays = list(parts)
        if not rays:
            rays.append((np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2, 3)), np.zeros((0, 2))))
        if len(rays) == 1:
            return self.locate_rays(*rays[0])
        return self.locate_rays(*(np.concatenate(p) for p in zip(*rays, strict=True)))

    def locate_rays(
        self,
        origins_enu: np.ndarray,
        directions_enu: np.ndarray,
        perturb_axes_enu: np.ndarray,
        perturb_sigmas_rad: np.ndarray,
    ) -> HitBatch:
        """Terrain crossings and road-rule points of a batch of rays, as arrays.

        Parameters
        ----------
        origins_enu, directions_enu : ndarray, shape (n, 3)
            The rays, site frame (m); unit directions.
        perturb_axes_enu : ndarray, shape (n, 2, 3)
            Per ray, the unit directions in which it tips as its pixel moves.
        perturb_sigmas_rad : ndarray, shape (n, 2)
            Per ray, the 1-sigma pointing error along those directions (rad).

        Returns
        -------
        HitBatch
        """
        o = np.asarray(origins_enu, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions_enu, dtype=np.float64).reshape(-1, 3)
        axes = np.asarray(perturb_axes_enu, dtype=np.float64).reshape(len(o), 2, 3)
        sig = np.asarray(perturb_sigmas_rad, dtype=np.float64).reshape(len(o), 2)
        n = len(o)
        if self._tiled is not None:
            result = self._tiled.cast(o, d, self.max_range_m, mode="all")
        else:
            result = cast_rays(self.dem, o, d, self.max_range_m, mode="all")
        counts = np.diff(result.offsets)
        ray_of_hit = np.repeat(np.arange(n), counts)
        roads = self.roads
        if roads is not None and len(roads):
            choice = roads.best_candidates(o, d, self.dem, self.road_cutoff_m, self.road_max_gap_m)
            road_rays = np.flatnonzero(choice.found)
            road_p = choice.p_enu[road_rays]
            road_rng = np.linalg.norm(road_p - o[road_rays], axis=1)
        else:
            road_rays = np.zeros(0, np.int64)
            road_p = np.zeros((0, 3))
            road_rng = np.zeros(0)
        # Terrain hits and road points take one pass: every step is per point.
        ray_all = np.concatenate([ray_of_hit, road_rays])
        p_all = np.concatenate([result.points, road_p])
        rng_all = np.concatenate([result.range_m, road_rng])
        x, y = p_all[:, 0], p_all[:, 1]
        gx, gy = self.dem.gradient(x, y)
        grad = np.column_stack([_finite_or_zero(gx), _finite_or_zero(gy)])
        var_z = _finite_or_zero(self.dem.sample_variance(x, y))
        cov = hit_covariances(
            d[ray_all], rng_all, grad, axes[ray_all], sig[ray_all], np.sqrt(np.maximum(var_z, 0))
        )
        m = len(result.range_m)
        road_all = np.empty(n * 8)  # one buffer: point (3), range, covariance (4)
        road_all.fill(np.nan)
        road_enu = road_all[: 3 * n].reshape(n, 3)
        road_range = road_all[3 * n : 4 * n]
        road_cov = road_all[4 * n :].reshape(n, 2, 2)
        road_enu[road_rays] = road_p
        road_range[road_rays] = road_rng
        road_cov[road_rays] = cov[m:]
        return HitBatch(
            origins_enu=o,
            directions_enu=d,
            status=np.asarray(result.status),
            crossed_nodata=np.asarray(result.crossed_nodata),
            offsets=np.asarray(result.offsets),
            points_enu=np.asarray(result.points),
            range_m=np.asarray(result.range_m),
            cov_en_m2=cov[:m],
            road_enu=road_enu,
            road_range_m=road_range,
            road_cov_en_m2=road_cov,
        )

    def _ground_hit_objects(
        self, batch: HitBatch
    ) -> tuple[list[GroundHit], list[GroundHit | None]]:
        """GroundHit values of a batch: every terrain hit, and each ray's road point."""
        has_road = batch.has_road
        road_rays = np.flatnonzero(has_road)
        pts = np.concatenate([batch.points_enu, batch.road_enu[road_rays]])
        if len(pts):
            lat, lon, h = (
                np.atleast_1d(a).tolist()
                for a in self.frame.to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2])
            )
        else:
            lat = lon = h = []
        rng = batch.range_m.tolist() + batch.road_range_m[road_rays].tolist()
        sigma = batch.sigma_m.tolist() + batch.road_sigma_m[road_rays].tolist()
        cov = list(batch.cov_en_m2) + list(batch.road_cov_en_m2[road_rays])
        m = len(batch.range_m)
        made = [
            GroundHit(
                pts[k].copy(),
                lat[k],
                lon[k],
                h[k],
                rng[k],
                sigma[k],
                cov[k],
                "terrain" if k < m else "road",
            )
            for k in range(len(pts))
        ]
        roads: list[GroundHit | None] = [None] * len(has_road)
        for j, r in enumerate(road_rays.tolist()):
            roads[r] = made[m + j]
        return made[:m], roads

    @staticmethod
    def _select(
        hits: tuple[GroundHit, ...], road: GroundHit | None, rule: str
    ) -> tuple[GroundHit, ...]:
        if rule == "all":
            return hits
        if rule == "road":
            return (road,) if road is not None else ()
        if not hits:
            return ()
        return (hits[0],) if rule == "first" else (hits[-1],)


def _pixels(camera, u: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validated pixel arrays of ``camera``: same length, inside the image."""
    u_arr = np.atleast_1d(np.asarray(u, dtype=np.float64))
    v_arr = np.atleast_1d(np.asarray(v, dtype=np.float64))
    if u_arr.shape != v_arr.shape:
        raise CameraError("u and v must have the same length")
    intr = camera.intrinsics
    bad = ~intr.in_image(u_arr, v_arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise CameraError(
            f"pixel ({u_arr[i]:g}, {v_arr[i]:g}) is outside the {intr.width}x{intr.height} image"
        )
    return u_arr, v_arr


def _worst_sigma(cov: np.ndarray) -> np.ndarray:
    """Square root of the largest eigenvalue of each 2x2 covariance ``(k, 2, 2)``: (k,).

    LAPACK takes the matrices one by one, so each value is the same whatever else is
    in the call.
    """
    return np.sqrt(np.linalg.eigvalsh(cov)[:, -1]) if len(cov) else np.zeros(0)


def _finite_or_zero(a: np.ndarray) -> np.ndarray:
    """``np.nan_to_num(a)``, without its work when every value is finite already."""
    return a if np.isfinite(a).all() else np.nan_to_num(a)


def _rays_and_perturbations(
    camera: Camera, u: np.ndarray, v: np.ndarray, sigma_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``camera.pixel_to_ray(u, v)`` and :func:`_pixel_perturbations`, undistorting once.

    The same arithmetic in the same order as the two calls, so the same bits; the unit
    ray of the perturbations is the ray's camera-frame direction.
    """
    intr = camera.intrinsics
    xn, yn = intr.undistort(u, v)
    ray = np.empty((len(xn), 3))  # np.stack([xn, yn, 1], axis=-1) in one allocation
    ray[:, 0], ray[:, 1], ray[:, 2] = xn, yn, 1.0
    norm = np.linalg.norm(ray, axis=-1, keepdims=True)
    unit = ray / norm
    rot_t = camera.R_world_cam.T
    directions = unit @ rot_t
    origins = np.empty_like(directions)
    origins[:] = camera.position_enu
    axes, sig = _perturbations_from_unit(intr, xn, yn, unit, norm, rot_t, sigma_px)
    return origins, directions, axes, sig


def _perturbations_from_unit(
    intr,
    xn: np.ndarray,
    yn: np.ndarray,
    unit: np.ndarray,
    norm: np.ndarray,
    rot_t: np.ndarray,
    sigma_px: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The body of :func:`_pixel_perturbations` after its unit rays are known."""
    a, b, c, d = distortion_jacobian(xn, yn, *intr.lens_coeffs)
    det = a * d - b * c
    n = len(xn)
    # Columns of the inverse Jacobian, per pixel: d(xn, yn)/du and d(xn, yn)/dv.
    d_du = np.zeros((n, 3))
    d_du[:, 0] = d / (det * intr.fx)
    d_du[:, 1] = -c / (det * intr.fx)
    d_dv = np.zeros((n, 3))
    d_dv[:, 0] = -b / (det * intr.fy)
    d_dv[:, 1] = a / (det * intr.fy)
    turn = np.empty((n, 2, 3))  # d(unit ray)/d(u, v), site frame, rad/px
    for k, dray in enumerate((d_du, d_dv)):
        perp = dray - unit * np.sum(unit * dray, axis=-1, keepdims=True)
        turn[:, k] = (perp / norm) @ rot_t
    speed = np.linalg.norm(turn, axis=-1)
    return turn / speed[..., None], sigma_px * speed


def _pixel_perturbations(
    camera, u: np.ndarray, v: np.ndarray, sigma_px: float
) -> tuple[np.ndarray, np.ndarray]:
    """How each pixel's unit ray turns as its column and row change.

    Returns
    -------
    axes : ndarray, shape (n, 2, 3)
        Unit directions (site frame, perpendicular to the ray) in which the ray tips as
        ``u`` and as ``v`` grow.
    sigmas_rad : ndarray, shape (n, 2)
        The angle the ray turns for a ``sigma_px`` change of ``u`` and of ``v``.

    Notes
    -----
    The rate is exact through the lens model: ``d(xn, yn)/d(u, v)`` is the inverse of the
    distortion Jacobian scaled by ``1/fx, 1/fy``, and the unit ray ``D / |D|`` with
    ``D = (xn, yn, 1)`` turns by the part of ``dD`` perpendicular to it, over ``|D|``.
    Taking the camera's x and y axes with ``sigma_px / f`` instead overstates the angle by
    ``|D|`` off the optical axis (12 % at the corners of a 640 x 480 image with f = 800 px).

    :meth:`Geolocator.locate_pixels` uses :func:`_rays_and_perturbations` for a
    :class:`Camera` (one undistortion for the ray and this); this stays the reference
    it is tested against, bit for bit, and the path for other camera types.
    """
    intr = camera.intrinsics
    xn, yn = intr.undistort(u, v)
    a, b, c, d = distortion_jacobian(xn, yn, *intr.lens_coeffs)
    det = a * d - b * c
    # Columns of the inverse Jacobian, per pixel: d(xn, yn)/du and d(xn, yn)/dv.
    zero = np.zeros_like(xn)
    d_du = np.stack([d / (det * intr.fx), -c / (det * intr.fx), zero], axis=-1)
    d_dv = np.stack([-b / (det * intr.fy), a / (det * intr.fy), zero], axis=-1)
    ray = np.stack([xn, yn, np.ones_like(xn)], axis=-1)
    norm = np.linalg.norm(ray, axis=-1, keepdims=True)
    unit = ray / norm
    rates = []
    for dray in (d_du, d_dv):
        perp = dray - unit * np.sum(unit * dray, axis=-1, keepdims=True)
        rates.append((perp / norm) @ np.asarray(camera.R_world_cam, dtype=np.float64).T)
    turn = np.stack(rates, axis=1)  # (n, 2, 3): d(unit ray)/d(u, v), site frame, rad/px
    speed = np.linalg.norm(turn, axis=-1)
    return turn / speed[..., None], sigma_px * speed
