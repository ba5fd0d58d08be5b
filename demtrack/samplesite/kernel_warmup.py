"""Compile the sample-site build's numba kernels in child processes, beside the build.

On a machine with an empty numba cache the sample-site build would spend most of its time
compiling the ray-casting kernels that render the camera views. The build renders with the
light kernels (``core.raycast._light_kernels``: the same answers, a quarter of the compile);
each job here compiles one share of what it and a cold ``demtrack demo`` need on a tiny
synthetic DEM, in its own process, and leaves the machine code in numba's on-disk cache;
the build meanwhile scans the world and grids the DEM and orthophoto, then waits for the
``cast`` job and loads the kernels from the cache:

``cast``
    Everything a camera render calls: the undistortion kernel, the ray checks, the light
    pyramid walk (``cast_kernel_light``) and the hit gather (with light kernels on, the
    min/max pyramid is built in numpy). That is also all a cold console's casts need
    until its warm-up is done (all-hits casts re-cast their rare many-hit rays with the
    same kernel). The build waits for this job only.
``pyramid``
    The min/max pyramid kernel alone (the ``server`` job compiles it too).
``server``
    The fast kernels the console server's start-up warm-up loads (``cast_kernel``, the
    all-hits re-walk, the pyramid, the run detector); started with ``cast`` at the lowest
    CPU priority, so it takes only the CPU the build and the server's start leave.
``tracker``
    The live tracker's fusion and Kalman kernels (``core.warm.warm_tracking``: about 16 s of CPU
    cold, about 1 s from the cache). A warm ``demtrack demo`` starts it with ``server``.
``kalman``
    The Kalman kernels alone (prediction, gating, update, smoothing: the walk of
    ``core.warm.warm_tracking`` seen by one camera; about 10 s of CPU cold).
``fusion``
    The two-camera fusion kernels alone (the walk's first step: about 5 s). With
    ``kalman``, exactly what ``tracker`` compiles, in two processes so that two cores can
    share it: a cold ``demtrack demo`` starts both with ``server``, at a low priority
    (above ``server``'s), so they take the CPU the build leaves and no longer slow the
    ``cast`` job and the renders the first page waits for.

``demtrack demo``'s replay waits for whichever of these it started
(``app.state.replay_after``), so no replayed detection waits for the replay thread to
compile the tracker's kernels.

The angular-index kernels are never compiled here. Each job compiles exactly the
specialisations the build and the server use (the same dtypes, layouts and read-only
flags); ``tests/samplesite/test_kernel_warmup.py`` checks that against a real render and
a light-kernel session of the console's casts.
Run as ``python -m demtrack.samplesite.kernel_warmup JOB``.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

__all__ = ["JOBS", "TRACKER_JOBS", "KernelWarmers", "load_numba_target", "run_job"]

#: Job names, in the order they are best started.
JOBS = ("cast", "pyramid", "fusion", "kalman", "tracker", "server")
#: CPU priority (``nice``) of each job's process. The build waits for ``cast``: it keeps
#: full priority beside the parent's scan; ``server`` only uses CPU nothing else wants.
_NICE = {"cast": 0, "pyramid": 5, "fusion": 15, "kalman": 15, "tracker": 2, "server": 19}
#: The jobs that compile the live tracker's kernels.
TRACKER_JOBS = ("fusion", "kalman", "tracker")


def _tiny_scene() -> tuple[Any, np.ndarray, Any, Any]:
    """A 4 x 4 DEM, a 2 x 2 orthophoto and a small camera looking down at it."""
    import numpy as np

    from demtrack.core.camera.pinhole import Camera, Intrinsics
    from demtrack.core.terrain.dem import Dem
    from demtrack.core.terrain.grid import GridSpec

    elev = np.arange(16, dtype=np.float32).reshape(4, 4)
    dem = Dem(GridSpec(0.0, 4.0, 1.0, 4, 4), elev)
    ortho_grid = GridSpec(0.0, 4.0, 2.0, 2, 2)
    ortho = np.zeros((2, 2, 3), np.uint8)
    # Mild barrel distortion, as every sample-site camera has: the undistortion kernel runs.
    intr = Intrinsics(8.0, 8.0, 3.5, 2.5, 8, 6, k1=-0.04)
    camera = Camera.from_azimuth_tilt_roll(intr, [2.0, 2.0, 100.0], 0.0, -89.0)
    return dem, ortho, ortho_grid, camera


def _job_cast() -> None:
    from demtrack.core.raycast.light import light_kernels
    from demtrack.core.site.render import render_view

    dem, ortho, ortho_grid, camera = _tiny_scene()
    with light_kernels():  # as the build renders: the pyramid is built in numpy
        render_view(camera, dem, ortho, ortho_grid)


def _job_pyramid() -> None:
    from demtrack.core.raycast.pyramid import build_pyramid

    dem, _, _, _ = _tiny_scene()
    build_pyramid(dem.elevation)


def _job_server() -> None:
    from demtrack.core.warm import warm_up

    # What server.app warms at start-up but the tracker (its own jobs): no angular index.
    warm_up(("raycast", "lens"), angular=False)


def _job_tracker(part: str = "all") -> None:
    from demtrack.core.warm import warm_up

    # The whole walk, or one of its shares (core.warm.TRACKING_PARTS).
    warm_up(("tracking",), tracker_part=part)


_JOB_FUNCS: dict[str, Callable[[], None]] = {
    "cast": _job_cast,
    "pyramid": _job_pyramid,
    "fusion": functools.partial(_job_tracker, "fusion"),
    "kalman": functools.partial(_job_tracker, "kalman"),
    "tracker": _job_tracker,
    "server": _job_server,
}


def run_job(name: str) -> None:
    """Compile (or load from numba's cache) the kernels of job ``name`` in this process."""
    _JOB_FUNCS[name]()


def load_numba_target() -> None:
    """Set up numba's CPU target in this process, as its first kernel load would.

    That first load imports numba's typing and lowering registries (about 1 s of CPU);
    a process about to wait for a warm-up job can do it while it waits.
    """
    from numba.core.registry import cpu_target

    cpu_target.target_context.refresh()


def _lower_priority(nice: int) -> Any:
    """A ``preexec_fn`` that lowers the child's CPU priority by ``nice`` (None for 0).

    19, the lowest, also takes Linux's ``SCHED_IDLE`` policy where it can: nice 19 still
    weighs about a third of nice 15 against the tracker's jobs, an idle-policy process
    almost nothing, so the ``server`` job then runs on CPU time nothing else wants.
    """
    if nice <= 0:
        return None

    def lower() -> None:
        os.nice(nice)
        if nice >= 19 and hasattr(os, "SCHED_IDLE"):
            try:
                os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
            except OSError:  # not allowed here: nice 19 alone
                pass

    return lower


class KernelWarmers:
    """Child processes running warm-up jobs; :meth:`wait` joins them.

    A job that fails only costs time: the build then compiles what is missing itself.
    """

    def __init__(self, procs: Sequence[subprocess.Popen], jobs: Sequence[str] = ()) -> None:
        self.procs = list(procs)
        self.jobs = list(jobs)  # the job each process runs, when known

    @classmethod
    def start(cls, jobs: Sequence[str] = ("cast",)) -> KernelWarmers:
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
        return cls(procs, jobs)

    def wait(self, jobs: Sequence[str] | None = None) -> list[int]:
        """Wait for every child (or those running ``jobs``); their exit statuses."""
        if jobs is None:
            return [p.wait() for p in self.procs]
        return [p.wait() for p, job in zip(self.procs, self.jobs, strict=False) if job in jobs]

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
