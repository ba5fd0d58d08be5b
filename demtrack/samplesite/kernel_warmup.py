"""Compile the sample-site build's numba kernels in child processes, beside the build.

On a machine with an empty numba cache the sample-site build spends most of its time
compiling the ray-casting kernels that render the camera views (``cast_kernel`` alone is
over half of it). Each job here compiles one share of them on a tiny synthetic DEM, in its
own process, and leaves the machine code in numba's on-disk cache; the build meanwhile
scans the world and grids the DEM and orthophoto, then waits for the jobs and loads the
kernels from the cache. Two jobs split the compile between two cores:

``cast``
    Everything a camera render calls except the pyramid build: the undistortion kernel,
    the ray checks, the first-hit pyramid walk (``cast_kernel``) and the hit gather.
``pyramid``
    The min/max pyramid build, plus the small run detector every server cast calls
    (``origin_runs_kernel``).
``server``
    What the console server's start-up warm-up adds (the all-hits re-walk and its hit
    points); run after the other two, at low priority, while the server starts.

The angular-index kernels are never compiled here. Each job compiles exactly the
specialisations the build and the server use (the same dtypes, layouts and read-only
flags); ``tests/samplesite/test_kernel_warmup.py`` checks that against a real render.
Run as ``python -m demtrack.samplesite.kernel_warmup JOB``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

__all__ = ["JOBS", "KernelWarmers", "run_job"]

#: Job names, in the order they are best started.
JOBS = ("cast", "pyramid", "server")
#: CPU priority (``nice``) of each job's process. ``cast`` is the longest compile and the
#: build waits for it: it keeps full priority, so the parent's scan and the ``pyramid``
#: job share the other core; ``server`` only uses CPU that nothing else wants.
_NICE = {"cast": 0, "pyramid": 5, "server": 19}


def _tiny_scene() -> tuple[Any, np.ndarray, Any, Any]:
    """A 4 x 4 DEM, a 2 x 2 orthophoto and a small camera looking down at it."""
    import numpy as np

    from demtrack.core.camera import Camera, Intrinsics
    from demtrack.core.dem import Dem
    from demtrack.core.grid import GridSpec

    elev = np.arange(16, dtype=np.float32).reshape(4, 4)
    dem = Dem(GridSpec(0.0, 4.0, 1.0, 4, 4), elev)
    ortho_grid = GridSpec(0.0, 4.0, 2.0, 2, 2)
    ortho = np.zeros((2, 2, 3), np.uint8)
    # Mild barrel distortion, as every sample-site camera has: the undistortion kernel runs.
    intr = Intrinsics(8.0, 8.0, 3.5, 2.5, 8, 6, k1=-0.04)
    camera = Camera.from_azimuth_tilt_roll(intr, [2.0, 2.0, 100.0], 0.0, -89.0)
    return dem, ortho, ortho_grid, camera


def _pyramid_by_numpy(
    elev: np.ndarray, nodes: np.ndarray, offsets: np.ndarray, shapes: np.ndarray
) -> tuple[float, float]:
    """Stand-in for ``build_pyramid_kernel`` (same arguments and result), in plain numpy."""
    import numpy as np

    from demtrack.core.raycast_reference import pyramid_reference

    levels = pyramid_reference(elev)[1:]
    for level, start, (rows, cols) in zip(levels, offsets, shapes, strict=True):
        nodes[start : start + rows * cols] = level.reshape(-1, 2)
    finite = elev[np.isfinite(elev)]
    return float(finite.min()), float(finite.max())


def _job_cast() -> None:
    from demtrack.core import pyramid
    from demtrack.core.render import render_view

    dem, ortho, ortho_grid, camera = _tiny_scene()
    # The pyramid is left to the ``pyramid`` job: build this one without its kernel.
    real = pyramid.build_pyramid_kernel
    pyramid.build_pyramid_kernel = _pyramid_by_numpy
    try:
        dem.ray_caster()
    finally:
        pyramid.build_pyramid_kernel = real
    render_view(camera, dem, ortho, ortho_grid)


def _job_pyramid() -> None:
    import numpy as np

    from demtrack.core import angular_kernels
    from demtrack.core.pyramid import build_pyramid

    dem, _, _, _ = _tiny_scene()
    build_pyramid(dem.elevation)
    # Every cast with ``coherent=None`` (the server's) first looks for runs of one origin.
    o = np.zeros((2, 3), np.float64)
    angular_kernels.origin_runs_kernel(o, 1)


def _job_server() -> None:
    import numpy as np

    from demtrack.core.camera import undistort_normalized_nb
    from demtrack.core.raycast import warm_up

    warm_up(angular=False)  # what server.app warms at start-up, angular index excluded
    undistort_normalized_nb(np.array([0.1]), np.array([0.1]), -0.04, 0.0, 0.0, 0.0, 0.0)


_JOB_FUNCS = {"cast": _job_cast, "pyramid": _job_pyramid, "server": _job_server}


def run_job(name: str) -> None:
    """Compile (or load from numba's cache) the kernels of job ``name`` in this process."""
    _JOB_FUNCS[name]()


def _lower_priority(nice: int) -> Any:
    """A ``preexec_fn`` that lowers the child's CPU priority by ``nice`` (None for 0)."""
    if nice <= 0:
        return None

    def lower() -> None:
        os.nice(nice)

    return lower


class KernelWarmers:
    """Child processes running warm-up jobs; :meth:`wait` joins them.

    A job that fails only costs time: the build then compiles what is missing itself.
    """

    def __init__(self, procs: Sequence[subprocess.Popen]) -> None:
        self.procs = list(procs)

    @classmethod
    def start(cls, jobs: Sequence[str] = ("cast", "pyramid")) -> KernelWarmers:
        """Start one child per job, each at its job's CPU priority."""
        unknown = [j for j in jobs if j not in _JOB_FUNCS]
        if unknown:
            raise ValueError(f"unknown warm-up job(s): {', '.join(unknown)}")
        procs = []
        for job in jobs:
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-m", "demtrack.samplesite.kernel_warmup", job],
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    preexec_fn=_lower_priority(_NICE[job]),
                )
            )
        return cls(procs)

    def wait(self) -> list[int]:
        """Wait for every child; their exit statuses."""
        return [p.wait() for p in self.procs]

    def stop(self) -> None:
        """End children still running (a build that failed no longer needs them)."""
        for p in self.procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m demtrack.samplesite.kernel_warmup JOB ...``."""
    for job in sys.argv[1:] if argv is None else argv:
        run_job(job)
    return 0


if __name__ == "__main__":
    sys.exit(main())
