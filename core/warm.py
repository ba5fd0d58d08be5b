"""Kernel warm-up: compile (or load from numba's on-disk cache) every engine kernel.

One entry point, :func:`warm_up`, over the engines in :data:`ENGINES`: the DEM ray caster
(``core.raycast``), the lens undistortion (``core.camera.lens``), the terrain surface
(``core.terrain.surface``), the viewshed (``core.visibility``) and the tracker
(``core.tracking``). Each engine is warmed on a tiny scene that passes the kernels the
exact argument types real calls pass (read-only float32 rasters, writable C arrays of
rays, read-only fix arrays ...), so that nothing compiles again on the first real request.
The server warms :data:`SERVER_ENGINES` at start-up; the sample-site build's warm-up jobs
(``demtrack.samplesite.kernel_warmup``) warm shares of them in child processes.

Nothing here runs at import: the scenes are built when a warm-up is called.
"""

from __future__ import annotations

from collections.abc import Iterable
from types import SimpleNamespace

import numpy as np

from .camera.lens import undistort_normalized_nb
from .camera.pinhole import Camera, Intrinsics
from .geolocation._posed_kernels import undistort_each
from .raycast import _ray_kernels
from .raycast.cast import RayCaster
from .raycast.light import use_light_kernels
from .raycast.pyramid import build_pyramid
from .terrain.dem import Dem
from .terrain.grid import GridSpec
from .terrain.surface import bilinear_sample
from .tracking.methods import run_tracker
from .tracking.types import Fix
from .visibility.viewshed import viewshed

__all__ = [
    "ENGINES",
    "SERVER_ENGINES",
    "TRACKING_PARTS",
    "warm_lens",
    "warm_raycast",
    "warm_surface",
    "warm_tracking",
    "warm_up",
    "warm_viewshed",
]

#: Every engine with numba kernels, in the order :func:`warm_up` warms them.
ENGINES = ("raycast", "lens", "surface", "viewshed", "tracking")
#: What the console's requests and live tracker use (the server's start-up warm-up).
SERVER_ENGINES = ("raycast", "lens", "surface", "tracking")
#: Shares of the tracker's walk, for compiling its kernels in separate processes:
#: ``fusion`` is the first step's pair of fixes (fused, a track started with nothing to
#: predict yet), ``kalman`` what one camera sees (no pair to fuse, every Kalman and gating
#: kernel). Together they compile exactly what the whole walk (``all``) compiles.
TRACKING_PARTS = ("all", "fusion", "kalman")


def warm_up(
    engines: Iterable[str] = ENGINES,
    *,
    angular: bool = True,
    tracker_method: str = "kalman",
    tracker_part: str = "all",
) -> None:
    """Compile (or load from numba's cache) the kernels of ``engines``.

    Parameters
    ----------
    engines : iterable of str
        Names from :data:`ENGINES`; warmed in :data:`ENGINES` order.
    angular : bool
        Ray casts: also the angular-index kernels and the sort of large incoherent
        batches (see :func:`warm_raycast`).
    tracker_method : str
        Tracking method (``core.tracking.METHODS``) whose kernels to compile.
    tracker_part : str
        Share of the tracker's walk (:data:`TRACKING_PARTS`).

    Raises
    ------
    ValueError
        On an unknown engine or tracker part.
    """
    wanted = set(engines)
    unknown = sorted(wanted - set(ENGINES))
    if unknown:
        raise ValueError(
            f"unknown warm-up engine {unknown[0]!r}: want some of {', '.join(ENGINES)}"
        )
    if "raycast" in wanted:
        warm_raycast(angular=angular)
    if "lens" in wanted:
        warm_lens()
    if "surface" in wanted:
        warm_surface()
    if "viewshed" in wanted:
        warm_viewshed()
    if "tracking" in wanted:
        warm_tracking(tracker_method, part=tracker_part)


# ------------------------------------------------------------------------- ray casts
def warm_raycast(angular: bool = True) -> None:
    """Compile every ray-casting kernel, on a tiny DEM.

    From the on-disk cache this takes well under a second; cold, about 25 s of CPU for
    the pyramid kernels and about 60 s more for the angular-index kernels.

    Parameters
    ----------
    angular : bool
        Also compile the angular-index kernels, used only by casts of at least
        ``MIN_COHERENT_RUN`` rays from one origin (or ``coherent=True``), and the sort of
        batches of at least ``MIN_ORDERED_RAYS`` rays without shared origins.

    Notes
    -----
    It always warms the fast kernels, then turns the light ones off
    (:func:`~demtrack.core.raycast.light.use_light_kernels`): casts switch to the fast
    kernels once they are ready.
    """
    elev = np.arange(16, dtype=np.float32).reshape(4, 4)
    elev[0, 0] = np.nan
    build_pyramid(elev)  # the kernel, even while light kernels are on
    caster = RayCaster.from_dem(SimpleNamespace(grid=GridSpec(0.0, 4.0, 1.0, 4, 4), elevation=elev))
    o = np.array([[2.0, 2.0, 100.0], [0.5, 3.5, 100.0]])
    d = np.array([[0.1, 0.1, -1.0], [0.0, 0.0, -1.0]])
    # The fast kernels whatever the light switch says: other threads keep casting with
    # the light ones until these are ready.
    caster._cast(o, d, np.inf, "first", 256, None, light=False)
    caster._cast(o, d, np.inf, "all", 8, None, light=False)
    if angular:
        # The angular-index path (camera rays): build, cast, and the pyramid walk between
        # runs; and the sort of large incoherent batches. Both serve only batches of at
        # least 20,000 rays, which the server's requests are not: it warms without them
        # (about 7 s of CPU less in a cold start).
        _warm_angular(caster)
        g, rng = caster.grid, np.full(len(o), np.inf)
        copies = (np.empty_like(o), np.empty_like(d), np.empty_like(rng))
        geo = (float(g.x_min), float(g.y_max), float(g.cell_m), *g.shape, 1)
        _ray_kernels.ray_order_kernel(o, d, rng, *geo, *copies)
    # A level ray over a zig-zag crosses more often than the first pass keeps: this
    # compiles the re-walk kernel too.
    _zigzag_cast(None)
    use_light_kernels(False)


def _zigzag_cast(coherent: bool | None) -> None:
    """A level ray over a zig-zag: 12 crossings, more than either first pass keeps."""
    zig = np.tile(np.array([0.0, 10.0], np.float32), 12)
    zigzag = SimpleNamespace(grid=GridSpec(0.0, 2.0, 1.0, 2, 24), elevation=np.vstack([zig, zig]))
    RayCaster.from_dem(zigzag)._cast(
        np.array([[0.5, 1.0, 5.0]]),
        np.array([[1.0, 0.0, 0.0]]),
        np.inf,
        "all",
        256,
        coherent,
        light=False,
    )


def _warm_angular(caster: RayCaster) -> None:
    """Compile the angular-index kernels (build, cast, the walk between runs, re-walk)."""
    o3 = np.array([[2.0, 2.0, 100.0], [2.0, 2.0, 100.0], [0.5, 3.5, 100.0]])
    d3 = np.array([[0.1, 0.1, -1.0], [0.2, -0.1, -1.0], [0.0, 0.0, -1.0]])
    caster._cast(o3, d3, np.inf, "first", 256, True, light=False)
    caster._cast(o3, d3, np.inf, "all", 8, True, light=False)
    _zigzag_cast(True)


# ------------------------------------------------------------- lens, surface, viewshed
def warm_lens() -> None:
    """Compile the undistortion kernels (a distorted lens; a lens per pixel, zoom tables)."""
    undistort_normalized_nb(np.array([0.1]), np.array([0.1]), -0.04, 0.0, 0.0, 0.0, 0.0)
    undistort_each(np.array([0.1]), np.array([0.1]), np.array([[-0.04, 0, 0, 0, 0, 0.0]]),
                   np.array([np.inf]))  # fmt: skip


def warm_surface() -> None:
    """Compile the bilinear surface kernel for a read-only float32 raster (as a Dem's)."""
    grid = np.zeros((2, 2), np.float32)
    grid.setflags(write=False)  # as a Dem's rasters
    bilinear_sample(grid, np.array([0.5]), np.array([0.5]))


def warm_viewshed() -> None:
    """Compile the viewshed kernels: the sweep with its exact re-checks, and the exact path."""
    elev = np.zeros((8, 8), np.float32)
    elev[3:5, 3:5] = 6.0  # a block that hides the cells behind it
    dem = Dem(GridSpec(0.0, 8.0, 1.0, 8, 8), elev)
    camera = Camera.from_azimuth_tilt_roll(
        Intrinsics(8.0, 8.0, 3.5, 2.5, 8, 6), [1.0, 1.0, 3.0], 45.0, -10.0
    )
    for method in ("sweep", "exact"):
        viewshed(dem, camera, mode="reachable", max_range_m=50.0, method=method)


# ---------------------------------------------------------------------------- tracking
def _walk() -> list[Fix]:
    """An object walking in front of two cameras: a terrain and a crown hit per fix."""
    cams = {"a": np.array([-60.0, 0.0, 15.0]), "b": np.array([0.0, -70.0, 18.0])}
    cov = np.array([[[0.3, 0.05], [0.05, 0.6]], [[2.0, 0.0], [0.0, 2.0]]])
    fixes: list[Fix] = []
    for k in range(16):
        target = np.array([0.8 * k, 0.4 * k, 0.0])
        for name, origin in cams.items():
            crown = target + [2.0, -1.5, 4.0]
            fixes.append(
                Fix(
                    0.5 * k,
                    name,
                    "human",
                    len(fixes),
                    origin,
                    target - origin,
                    np.array([crown, target]),
                    np.array([1.4, 0.6]),
                    hit_cov_en_m2=cov,
                )
            )
    return fixes


def warm_tracking(method: str = "kalman", part: str = "all") -> None:
    """Track a tiny walk (or a :data:`TRACKING_PARTS` share of it) with ``method``.

    The tracker's kernels (fusion, Kalman, gating) are compiled for the exact argument
    types the tracker passes (read-only fix arrays, cached read-only motion matrices, ...),
    so the surest warm-up is the tracker itself on a few fixes. About 10 s of CPU with an
    empty numba cache, well under a second from it.

    Raises
    ------
    ValueError
        On an unknown ``part``.
    """
    fixes = _walk()
    if part == "fusion":
        fixes = [f for f in fixes if f.t_s == 0.0]
    elif part == "kalman":
        fixes = [f for f in fixes if f.sensor == "a"]
    elif part != "all":
        raise ValueError(f"unknown warm-up part {part!r}: want one of {', '.join(TRACKING_PARTS)}")
    run_tracker(fixes, method)
