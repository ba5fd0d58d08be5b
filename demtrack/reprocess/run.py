"""One reprocessing run from archive to outputs (what ``demtrack reprocess`` calls)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from demtrack.core.errors import InputFileError
from demtrack.core.tracking import METHODS, Track

from .archive import ArchiveRead
from .engines import RunResult, dask_client, run_dask, run_local
from .groups import sensor_groups
from .outputs import write_outputs
from .plan import Plan, make_plan
from .sources import read_archive

__all__ = ["ReprocessSettings", "plan_run", "reprocess"]


@dataclass(frozen=True)
class ReprocessSettings:
    """How a run is cut up and executed (none of it changes the outputs but ``method``).

    ``engine`` is ``"local"`` (this process) or ``"dask"`` (a new ``LocalCluster`` of
    ``workers`` processes, or the cluster at ``scheduler``). ``shuffle_seed`` and
    ``kill_after`` are for the tests: submit tasks in a shuffled order, kill a worker
    once that many tasks have finished. ``say`` prints a line (the dashboard's link).
    """

    method: str
    engine: str = "local"
    workers: int = 2
    scheduler: str | None = None
    quiet_s: float = 60.0
    window_s: float = 3600.0
    chunk_s: float = 600.0
    margin_m: float = 10.0
    progress: bool = False
    shuffle_seed: int | None = None
    kill_after: int | None = None
    say: Callable[[str], None] | None = None

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise InputFileError(
                f"unknown tracking method {self.method!r}; known: {sorted(METHODS)}"
            )
        if self.engine not in ("local", "dask"):
            raise InputFileError(f"unknown engine {self.engine!r} (use local or dask)")
        if self.workers < 1:
            raise InputFileError(f"--workers must be at least 1, got {self.workers}")


def plan_run(site_dir: str, archive: str, settings: ReprocessSettings) -> tuple[ArchiveRead, Plan]:
    """Read the archive and plan its tasks (sensor groups from the site's cameras)."""
    from demtrack.core.geolocation.fix_builder import sensor_sizes

    from .tasks import site_at

    site = site_at(site_dir)
    read = read_archive(archive, sensor_sizes(site))
    present = sorted(set(read.table["sensor"].to_pylist()))
    groups = sensor_groups(site, present, margin_m=settings.margin_m) if present else []
    plan = make_plan(
        read.table, groups, quiet_s=settings.quiet_s, window_s=settings.window_s,
        chunk_s=settings.chunk_s,
    )  # fmt: skip
    return read, plan


def _execute(
    plan: Plan, read: ArchiveRead, site_dir: str, s: ReprocessSettings
) -> tuple[RunResult, dict[str, Any]]:
    if s.engine == "local":
        return run_local(plan, read.table, site_dir, s.method), {"engine": "local"}
    with dask_client(s.workers, s.scheduler) as client:
        link = getattr(client, "dashboard_link", None)
        n_workers = len(client.scheduler_info().get("workers", {}))
        if s.progress and s.say is not None:
            s.say(f"dask: {n_workers} worker(s)" + (f", dashboard {link}" if link else ""))
        result = run_dask(
            plan, read.table, site_dir, s.method, client, shuffle_seed=s.shuffle_seed,
            kill_after=s.kill_after, progress=s.progress,
        )  # fmt: skip
        if s.progress and s.say is not None:
            s.say("")  # the progress bar's line ends without a newline
        return result, {
            "engine": "dask", "workers": n_workers, "scheduler": s.scheduler, **result.notes,
        }  # fmt: skip


def reprocess(
    site_dir: str | os.PathLike[str],
    archive: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    settings: ReprocessSettings,
    *,
    write_tracks: Callable[[Sequence[Track], Path], None] | None = None,
    tracks_name: str = "tracks.geojson",
) -> dict[str, Any]:
    """Reprocess ``archive`` on the site into ``out_dir``; returns the manifest.

    ``write_tracks(tracks, path)`` writes the tracks file (default:
    :func:`demtrack.server.track_export.write_track_file`, ``demtrack track``'s writers,
    each track's points converted to WGS84 in one call).
    """
    site_dir = os.fspath(site_dir)
    t0 = time.perf_counter()
    read, plan = plan_run(site_dir, os.fspath(archive), settings)
    t_plan = time.perf_counter() - t0
    result, run = _execute(plan, read, site_dir, settings)
    t_run = time.perf_counter() - t0 - t_plan
    if write_tracks is None:
        from demtrack.server.track_export import write_track_file

        from .tasks import site_at

        site = site_at(site_dir)

        def write_tracks(tracks: Sequence[Track], path: Path) -> None:
            write_track_file(site, tracks, path, batch_geodetic=True)

    info = {
        "method": settings.method,
        "archive": os.fspath(archive),
        "n_records": read.n_records,
        "n_detections": read.table.num_rows,
        "archive_skipped": dict(sorted(read.counts.items())),
    }
    run.update(plan_s=round(t_plan, 3), run_s=round(t_run, 3))
    return write_outputs(
        Path(out_dir), result, plan, tracks_name=tracks_name, write_tracks=write_tracks,
        info=info, run=run,
    )  # fmt: skip
