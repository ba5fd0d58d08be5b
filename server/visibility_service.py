"""Visibility for the map: per-sensor viewsheds as GeoJSON, the coverage raster, blind spots.

Everything here is computed by :func:`demtrack.core.visibility.viewshed.viewshed` (the
``"sweep"`` method, as ``demtrack viewshed`` does) for each sensor at its current pan and
tilt, and kept in a small bounded cache in the server state: a parameter set is computed
once. Site-frame coordinates are ENU metres; lon/lat are on the plane ``u = 0``. The
functions block (they compute): the routers call them in a worker thread.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

from demtrack.core.site.folder import Sensor
from demtrack.core.visibility.viewshed import blind_spot_labels, blind_spots, viewshed

from .imagery import png_bytes
from .state import ConsoleState

__all__ = [
    "COVERAGE_RGBA",
    "blind_spot_outlines",
    "coverage_png",
    "coverage_rgba",
    "coverage_summary",
    "sensor_viewshed_geojson",
    "viewshed_multipolygon",
]

#: Colour of a cell seen by 1, 2, 3 and 4 or more sensors (RGBA); unseen cells are clear.
COVERAGE_RGBA: tuple[tuple[int, int, int, int], ...] = (
    (255, 221, 51, 140),
    (255, 150, 20, 160),
    (230, 70, 30, 175),
    (160, 20, 90, 190),
)
#: Parameter sets kept (each holds a mask per sensor and its renderings).
_CACHE_ENTRIES = 48


class _Lru:
    """A bounded compute-once cache (least recently used entries go first)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.items: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self.lock = threading.RLock()

    def get(self, key: tuple[Any, ...], make: Callable[[], Any]) -> Any:
        with self.lock:  # held while computing: one request computes, the others wait
            if key in self.items:
                self.items.move_to_end(key)
                return self.items[key]
            value = make()
            self.items[key] = value
            while len(self.items) > self.size:
                self.items.popitem(last=False)
            return value


def _lru(state: ConsoleState) -> _Lru:
    return state.cached("visibility", lambda: _Lru(_CACHE_ENTRIES))


def _mask(
    state: ConsoleState, sensor: Sensor, mode: str, target_height_m: float, max_range_m: float
) -> np.ndarray:
    """The sensor's viewshed (bool, DEM grid shape), computed once per parameter set."""
    key = ("mask", sensor.id, sensor.pan_deg, sensor.tilt_deg, mode, target_height_m, max_range_m)

    def make() -> np.ndarray:
        m = viewshed(
            state.site.dem,
            sensor.camera,
            mode=mode,
            target_height_m=target_height_m,
            max_range_m=max_range_m,
            mount_yaw_deg=sensor.head.mount_yaw_deg,
        )
        m.setflags(write=False)
        return m

    return _lru(state).get(key, make)


def _count(state: ConsoleState, mode: str, target_height_m: float, max_range_m: float) -> Any:
    """Per-sensor masks and how many sensors see each cell (uint16, DEM grid shape)."""
    key = ("count", mode, target_height_m, max_range_m)

    def make() -> tuple[dict[str, np.ndarray], np.ndarray]:
        masks = {
            sid: _mask(state, state.site.sensors[sid], mode, target_height_m, max_range_m)
            for sid in sorted(state.site.sensors)
        }
        count = np.zeros(state.site.dem.grid.shape, np.uint16)
        for m in masks.values():
            count += m
        return masks, count

    return _lru(state).get(key, make)


def viewshed_multipolygon(mask: np.ndarray, transform: Any) -> list[list[list[list[float]]]]:
    """The True cells of ``mask`` as MultiPolygon coordinates (site frame, m).

    Cell squares are merged by ``rasterio.features.shapes`` (4-connected), so every edge
    lies on a cell boundary and a polygon covers exactly the centres of its cells. Rings
    follow RFC 7946: exteriors counter-clockwise, holes clockwise.
    """
    from rasterio.features import shapes
    from shapely.geometry import shape
    from shapely.geometry.polygon import orient

    m = np.ascontiguousarray(mask, dtype=np.uint8)
    out = []
    for geom, _ in shapes(m, mask=m.astype(bool), transform=transform, connectivity=4):
        poly = orient(shape(geom), sign=1.0)
        rings = [poly.exterior, *poly.interiors]
        out.append([[[float(x), float(y)] for x, y in r.coords] for r in rings])
    return out


def blind_spot_outlines(
    labels: np.ndarray, wanted: list[int], transform: Any
) -> list[list[list[list[list[float]]]]]:
    """The cells ``labels == k`` for each ``k`` in ``wanted``, as MultiPolygon coordinates.

    Each area is vectorised (:func:`viewshed_multipolygon`) within its bounding window
    only, so the cost follows the areas listed, not the grid. ``labels`` is
    :func:`~demtrack.core.visibility.viewshed.blind_spot_labels` (int, DEM grid shape); the answer
    is in the site frame (m) of ``transform``, edges on cell boundaries.
    """
    from rasterio.transform import Affine
    from scipy import ndimage

    boxes = ndimage.find_objects(labels, max_label=max(wanted, default=0))
    out = []
    for k in wanted:
        rs, cs = boxes[k - 1]
        origin = transform @ Affine.translation(cs.start, rs.start)  # the window's corner
        out.append(viewshed_multipolygon(labels[rs, cs] == k, origin))
    return out


def _to_lonlat(state: ConsoleState, polys: list[Any]) -> list[Any]:
    """Map MultiPolygon coordinates from the site frame to [lon, lat] (on the plane u = 0)."""
    flat = np.array([p for poly in polys for ring in poly for p in ring], float).reshape(-1, 2)
    if not len(flat):
        return []
    lat, lon, _ = state.site.frame.to_geodetic(flat[:, 0], flat[:, 1], np.zeros(len(flat)))
    ll = iter(zip(np.atleast_1d(lon).tolist(), np.atleast_1d(lat).tolist(), strict=True))
    return [[[list(next(ll)) for _ in ring] for ring in poly] for poly in polys]


def sensor_viewshed_geojson(
    state: ConsoleState,
    sensor: Sensor,
    mode: str,
    target_height_m: float,
    max_range_m: float,
    frame: str,
) -> dict[str, Any]:
    """GeoJSON FeatureCollection with one MultiPolygon: the cells ``sensor`` sees.

    ``frame``: ``"lonlat"`` (RFC 7946) or ``"enu"`` (site frame, m; the document then
    says so in ``frame``). ``properties.area_m2`` = cells x cell area.
    """

    def make() -> dict[str, Any]:
        mask = _mask(state, sensor, mode, target_height_m, max_range_m)
        g = state.site.dem.grid
        polys = viewshed_multipolygon(mask, g.transform)
        if frame == "lonlat":
            polys = _to_lonlat(state, polys)
        cells = int(mask.sum())
        doc: dict[str, Any] = {
            "type": "FeatureCollection",
            "features": [
                {
                    "type": "Feature",
                    "properties": {
                        "sensor": sensor.id,
                        "name": sensor.name,
                        "pan_deg": sensor.pan_deg,
                        "tilt_deg": sensor.tilt_deg,
                        "mode": mode,
                        "target_height_m": target_height_m,
                        "max_range_m": max_range_m,
                        "cells": cells,
                        "cell_m": g.cell_m,
                        "area_m2": cells * g.cell_m**2,
                    },
                    "geometry": {"type": "MultiPolygon", "coordinates": polys},
                }
            ],
        }
        if frame == "enu":
            doc["frame"] = "site ENU (m)"
        return doc

    key: tuple[Any, ...] = ("geojson", sensor.id, sensor.pan_deg, sensor.tilt_deg, mode)
    key += (target_height_m, max_range_m, frame)
    return _lru(state).get(key, make)


def coverage_rgba(count: np.ndarray) -> np.ndarray:
    """``(nrows, ncols, 4)`` uint8: :data:`COVERAGE_RGBA` by sensor count, clear where 0."""
    palette = np.array([(0, 0, 0, 0), *COVERAGE_RGBA], np.uint8)
    return palette[np.minimum(np.asarray(count), len(COVERAGE_RGBA))]


def coverage_png(
    state: ConsoleState, mode: str, target_height_m: float, max_range_m: float
) -> bytes:
    """PNG of how many sensors see each cell (:func:`coverage_rgba`, on the DEM grid)."""

    def make() -> bytes:
        _, count = _count(state, mode, target_height_m, max_range_m)
        return png_bytes(coverage_rgba(count))

    key = ("png", mode, target_height_m, max_range_m)
    data: bytes = _lru(state).get(key, make)
    return data


def coverage_summary(
    state: ConsoleState,
    mode: str,
    target_height_m: float,
    max_range_m: float,
    min_area_m2: float,
    limit: int,
) -> dict[str, Any]:
    """What ``demtrack viewshed`` prints, as JSON: areas per sensor, shares, blind spots.

    Blind spots are the 8-connected unseen areas of at least ``min_area_m2``, largest
    first, ``limit`` of them with their bounding box and outline (site frame, m).
    """

    def make() -> dict[str, Any]:
        site = state.site
        masks, count = _count(state, mode, target_height_m, max_range_m)
        cell_area = site.dem.grid.cell_m**2
        data_cells = int((~site.dem.nodata).sum())
        share = 1.0 / data_cells if data_cells else 0.0
        spots = blind_spots(count, site.dem, min_area_m2=min_area_m2)
        shown = spots[:limit]
        labels = blind_spot_labels(count, site.dem)
        outlines = blind_spot_outlines(labels, [b.label for b in shown], site.dem.grid.transform)
        e = np.array([b.centroid_e_m for b in shown], float)
        n = np.array([b.centroid_n_m for b in shown], float)
        lat, lon, _ = site.frame.to_geodetic(e, n, np.zeros(len(e)))
        return {
            "mode": mode,
            "target_height_m": target_height_m,
            "max_range_m": max_range_m,
            "cell_m": site.dem.grid.cell_m,
            "site_area_m2": data_cells * cell_area,
            "sensors": [
                {
                    "id": sid,
                    "name": site.sensors[sid].name,
                    "cells": int(m.sum()),
                    "area_m2": int(m.sum()) * cell_area,
                    "share": int(m.sum()) * share,
                }
                for sid, m in masks.items()
            ],
            "seen_by_at_least": {
                str(k): int((count >= k).sum()) * share for k in range(1, len(masks) + 1)
            },
            "legend": [
                {"count": k, "rgba": list(c), "or_more": k == len(COVERAGE_RGBA)}
                for k, c in enumerate(COVERAGE_RGBA, start=1)
            ],
            "min_area_m2": min_area_m2,
            "blind_spot_count": len(spots),
            "blind_spots": [
                {
                    "area_m2": b.area_m2,
                    "centroid_enu": [b.centroid_e_m, b.centroid_n_m],
                    "centroid_lonlat": [float(lo), float(la)],
                    "bbox_enu": list(b.bbox),
                    "outline_enu": outline,
                }
                for b, lo, la, outline in zip(
                    shown, np.atleast_1d(lon), np.atleast_1d(lat), outlines, strict=True
                )
            ],
        }

    key = ("json", mode, target_height_m, max_range_m, min_area_m2, limit)
    return _lru(state).get(key, make)
