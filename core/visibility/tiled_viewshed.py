"""Exact viewsheds and coverage over a tiled DEM, one output tile per task (Dask).

The in-memory exact viewshed (:func:`~demtrack.core.visibility.viewshed.viewshed` with
``method="exact"``) decides each cell on its own: target point above the cell centre, the
candidate tests (data, range, field of view or head limits), one sight line from the camera
cast to just short of the target. So an output tile is an independent task: it reads its
own cells of the tiled DEM (``core.terrain.tiled_dem``) and casts its sight lines with a
:class:`~demtrack.core.raycast.tiled_cast.TiledRayCaster` (one per worker process and file,
under a memory budget), with the same arithmetic per cell: the answers are the in-memory
exact viewshed's. Tiles wholly beyond the range are False without reading anything.

:func:`viewshed_tiles` and :func:`coverage_tiles` return lazy ``dask.array`` rasters; compute
them with a ``distributed`` client (a ``LocalCluster``, or a scheduler's address) or any
Dask scheduler, or write them out window by window. :func:`viewshed_window` is one task.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..camera.pinhole import Camera
from ..errors import CameraError
from ..raycast.tiled_cast import DEFAULT_MEMORY_BUDGET, TiledRayCaster
from ..terrain.tiled_dem import TiledDem
from .target_heights import DEFAULT_TARGET_HEIGHT_M
from .viewshed import (
    _BATCH,
    _TARGET_TOL_M,
    _TARGET_TOL_REL,
    EARTH_RADIUS_M,
    REFRACTION_K,
    PanTiltLimits,
    _reachable,
    _reaches_everywhere,
)

__all__ = ["coverage_tiles", "viewshed_tiles", "viewshed_window"]

#: This process's tiled casters, by file and budget (a Dask worker reuses its cache).
_CASTERS: dict[tuple[str, int], TiledRayCaster] = {}
_CASTERS_LOCK = threading.Lock()


def _caster(path: str, memory_budget: int) -> TiledRayCaster:
    key = (str(Path(path).resolve()), int(memory_budget))
    with _CASTERS_LOCK:
        if key not in _CASTERS:
            _CASTERS[key] = TiledRayCaster(TiledDem.open(path), int(memory_budget))
        return _CASTERS[key]


def _check(mode: str, max_range_m: float) -> None:
    if mode not in ("fov", "reachable"):
        raise CameraError(f"unknown viewshed mode {mode!r}; choose 'fov' or 'reachable'")
    if not (np.isfinite(max_range_m) and max_range_m > 0):
        raise CameraError(f"max_range_m must be positive, got {max_range_m!r}")


def _beyond_range(
    dem: TiledDem, window: tuple[int, int, int, int], c: np.ndarray, r: float
) -> bool:
    """No cell centre of the window is within ``r`` (horizontally, with a cell of slack)."""
    g = dem.grid
    r0, r1, c0, c1 = window
    x_lo, x_hi = g.x_min + c0 * g.cell_m, g.x_min + c1 * g.cell_m
    y_lo, y_hi = g.y_max - r1 * g.cell_m, g.y_max - r0 * g.cell_m
    dx = max(x_lo - c[0], 0.0, c[0] - x_hi)
    dy = max(y_lo - c[1], 0.0, c[1] - y_hi)
    return bool(np.hypot(dx, dy) > r + g.cell_m)


def viewshed_window(
    path: str,
    camera: Camera,
    window: tuple[int, int, int, int],
    *,
    mode: str = "fov",
    target_height_m: float = DEFAULT_TARGET_HEIGHT_M,
    max_range_m: float = 1000.0,
    mount_yaw_deg: float = 0.0,
    limits: PanTiltLimits | None = None,
    curvature: bool = False,
    memory_budget: int = DEFAULT_MEMORY_BUDGET,
) -> np.ndarray:
    """The exact viewshed on cells ``window = (r0, r1, c0, c1)`` of the tiled DEM at ``path``.

    Arguments as :func:`~demtrack.core.visibility.viewshed.viewshed` (``method="exact"``);
    ``memory_budget`` bytes of decoded blocks for this process's caster of ``path``.

    Returns
    -------
    ndarray, bool, shape ``(r1 - r0, c1 - c0)``
    """
    _check(mode, max_range_m)
    r0, r1, c0, c1 = window
    c = np.asarray(camera.position_enu, dtype=np.float64)
    out = np.zeros((r1 - r0, c1 - c0), bool)
    dem = TiledDem.open(path)
    if _beyond_range(dem, window, c, max_range_m):
        return out
    g = dem.grid
    th = float(target_height_m)
    curv = (1.0 - REFRACTION_K) / (2.0 * EARTH_RADIUS_M) if curvature else 0.0
    elev = dem.read_cells(r0, r1, c0, c1).astype(np.float64)
    # The target above each centre with viewshed's arithmetic, on global cell indices.
    q = np.arange(c0, c1, dtype=np.float64)[None, :]
    r = np.arange(r0, r1, dtype=np.float64)[:, None]
    x = np.broadcast_to(g.x_min + (q + 0.5) * g.cell_m, out.shape)
    y = np.broadcast_to(g.y_max - (r + 0.5) * g.cell_m, out.shape)
    z = (elev + th) - np.hypot(x - c[0], y - c[1]) ** 2 * curv
    dx, dy, dz = x - c[0], y - c[1], z - c[2]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz)
    with np.errstate(invalid="ignore"):
        cand = (dist == dist) & (dist > 0.0) & (dist <= max_range_m)
    idx = np.flatnonzero(cand)
    targets = np.column_stack([x.reshape(-1)[idx], y.reshape(-1)[idx], z.reshape(-1)[idx]])
    if mode == "fov":
        keep = camera.in_view(targets)
    elif not _reaches_everywhere(camera, limits or PanTiltLimits()):
        keep = _reachable(camera, mount_yaw_deg, limits or PanTiltLimits(), targets - c)
    else:
        keep = np.ones(len(idx), bool)
    idx, targets = idx[keep], targets[keep]
    if not len(idx):
        return out
    caster = _caster(path, memory_budget)
    d = targets - c
    seen = np.zeros(len(idx), bool)
    for k in range(0, len(d), _BATCH):
        sl = slice(k, k + _BATCH)
        reach = np.linalg.norm(d[sl], axis=1) * (1.0 - _TARGET_TOL_REL) - _TARGET_TOL_M
        origins = np.broadcast_to(c, (len(reach), 3))
        hits = caster.cast(origins, d[sl], np.maximum(reach, 0.0), mode="first")
        seen[sl] = hits.counts == 0
    out.reshape(-1)[idx] = seen
    return out


def _windows(dem: TiledDem, tile: int | None) -> tuple[int, list[int], list[int]]:
    side = int(tile or 2 * dem.tile)
    if side < 1:
        raise CameraError(f"output tile must be at least 1 cell, got {side}")
    g = dem.grid
    return side, list(range(0, g.nrows, side)), list(range(0, g.ncols, side))


def viewshed_tiles(
    path: str | Path,
    camera: Camera,
    *,
    tile: int | None = None,
    memory_budget: int = DEFAULT_MEMORY_BUDGET,
    **options: Any,
) -> Any:
    """The exact viewshed of ``camera`` over the tiled DEM at ``path``, as a lazy dask array.

    One task per output tile of ``tile x tile`` cells (default two DEM tiles a side);
    ``options`` as :func:`viewshed_window`. Returns a ``dask.array.Array`` of bool of the
    DEM's shape.
    """
    return _assemble(str(path), [camera], tile, memory_budget, options, coverage=False)


def coverage_tiles(
    path: str | Path,
    cameras: Sequence[Camera],
    *,
    tile: int | None = None,
    memory_budget: int = DEFAULT_MEMORY_BUDGET,
    **options: Any,
) -> Any:
    """How many of ``cameras`` see each cell (uint16), one task per output tile, lazily.

    The sum of each camera's :func:`viewshed_tiles` on the same tile, in one task.
    """
    if not len(cameras):
        raise CameraError("coverage needs at least one camera")
    return _assemble(str(path), list(cameras), tile, memory_budget, options, coverage=True)


def _tile_task(
    path: str,
    cameras: list[Camera],
    window: tuple[int, int, int, int],
    memory_budget: int,
    options: dict[str, Any],
    coverage: bool,
) -> np.ndarray:
    if not coverage:
        return viewshed_window(path, cameras[0], window, memory_budget=memory_budget, **options)
    count = np.zeros((window[1] - window[0], window[3] - window[2]), np.uint16)
    for cam in cameras:
        count += viewshed_window(path, cam, window, memory_budget=memory_budget, **options)
    return count


def _assemble(
    path: str,
    cameras: list[Camera],
    tile: int | None,
    memory_budget: int,
    options: dict[str, Any],
    coverage: bool,
) -> Any:
    import dask
    import dask.array as da

    _check(str(options.get("mode", "fov")), float(options.get("max_range_m", 1000.0)))
    dem = TiledDem.open(path)
    g = dem.grid
    side, rows, cols = _windows(dem, tile)
    dtype = np.uint16 if coverage else np.bool_
    task = dask.delayed(_tile_task, pure=True)
    blocks = []
    for r0 in rows:
        row = []
        for c0 in cols:
            win = (r0, min(r0 + side, g.nrows), c0, min(c0 + side, g.ncols))
            shape = (win[1] - win[0], win[3] - win[2])
            job = task(path, cameras, win, memory_budget, options, coverage)
            row.append(da.from_delayed(job, shape, dtype=dtype))
        blocks.append(row)
    return da.block(blocks)
