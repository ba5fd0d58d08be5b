"""Engines that run a :class:`~.plan.Plan`: in this process, or on a Dask cluster.

The local engine geolocates the plan's parts, then tracks its jobs (each segment's windows
in order). On Dask, a job is one task that geolocates its own detections and tracks them
(:mod:`.fused`: no fixes cross between workers, no job waits for another's geolocation),
a long segment's windows a chain of such tasks (each waits for the one before), the
longest jobs first; both call the same task functions (:mod:`.tasks`), and geolocation
does not depend on the batching, so their results are equal. A worker lost mid-run costs
its tasks a rerun (Dask recomputes what it held, from the inputs the client keeps).
"""

from __future__ import annotations

import os
import random
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa

from demtrack.core.errors import InputFileError

from .plan import Plan
from .tasks import (
    GeoResult,
    WindowResult,
    geolocate_part,
    segment_tracks,
    track_segments,
    track_window,
)

__all__ = ["RunResult", "dask_client", "run_dask", "run_local"]


@dataclass(frozen=True)
class RunResult:
    """What a run computed: each part's fixes and each segment's tracks (plan order)."""

    geo: list[GeoResult]
    tracks: list[list[Any]]
    notes: dict[str, Any] = field(default_factory=dict)


def _part_args(plan: Plan, table: pa.Table, k: int) -> tuple[pa.Table, Any]:
    part = plan.parts[k]
    return table.take(part.rows), part.rows


def _job_parts(plan: Plan, job: tuple[int, ...]) -> list[int]:
    return sorted({k for s in job for k in plan.segments[s].parts})


def _specs(plan: Plan, job: tuple[int, ...]) -> list[tuple[int, float, float]]:
    return [(plan.segments[s].seed, plan.segments[s].t_first, plan.segments[s].t_last) for s in job]


def _chained(plan: Plan, job: tuple[int, ...]) -> bool:
    return len(job) == 1 and len(plan.segments[job[0]].windows) > 1


def run_local(plan: Plan, table: pa.Table, site_dir: str, method: str) -> RunResult:
    """Run every task here, one after another."""
    geo = [geolocate_part(site_dir, *_part_args(plan, table, k)) for k in range(len(plan.parts))]
    tracks: list[list[Any]] = [[] for _ in plan.segments]
    for job in plan.jobs:
        if not _chained(plan, job):
            got = track_segments(
                site_dir, method, _specs(plan, job), [geo[k] for k in _job_parts(plan, job)]
            )
            for s, seg_tracks in zip(job, got, strict=True):
                tracks[s] = seg_tracks
            continue
        seg = plan.segments[job[0]]
        results: list[WindowResult] = []
        prev: WindowResult | None = None
        for w, window in enumerate(seg.windows):
            parts = [geo[k] for k in _window_parts(plan, seg.parts, window)]
            last = w == len(seg.windows) - 1
            bounds = (seg.t_first, seg.t_last)
            prev = track_window(site_dir, method, seg.seed, prev, parts, window, last, bounds)
            results.append(prev)
        tracks[job[0]] = segment_tracks(results)
    return RunResult(geo, tracks)


def _window_parts(plan: Plan, parts: tuple[int, ...], window: tuple[float, float]) -> list[int]:
    lo, hi = window
    return [k for k in parts if plan.parts[k].t_max >= lo and plan.parts[k].t_min < hi]


@contextmanager
def dask_client(workers: int, scheduler: str | None, timeout_s: float = 20.0) -> Any:
    """A client of ``scheduler``, or of a new ``LocalCluster`` of ``workers`` processes.

    The local cluster's workers run one thread each, and numba one thread too
    (``NUMBA_NUM_THREADS=1``): the parallelism is Dask's.
    """
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=timeout_s)
        except (OSError, TimeoutError) as exc:
            raise InputFileError(f"cannot reach the Dask scheduler {scheduler!r}: {exc}") from exc
        try:
            yield client
        finally:
            client.close()
        return
    env = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",
        env=env,
    )
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def _kill_one_worker(client: Any) -> str:
    """Make one worker process exit at once (its nanny starts a new one); its address."""
    addr = sorted(client.scheduler_info()["workers"])[0]
    try:
        client.run(os._exit, 1, workers=[addr])
    except Exception:  # noqa: BLE001, S110  (the worker is gone: that was the point)
        pass
    return str(addr)


def _submit_fused(
    plan: Plan,
    table: pa.Table,
    seg_rows: tuple[Any, ...],
    run: tuple[str, str, Any],
    order: list[int],
) -> dict[int, list[Any]]:
    """Each job's task(s), longest job first (Dask runs higher ``priority`` first)."""
    from .fused import track_job, track_window_rows

    site_dir, method, client = run
    chains: dict[int, list[Any]] = {}
    for j in order:
        job = plan.jobs[j]
        n_rows = sum(len(seg_rows[s]) for s in job)
        if not _chained(plan, job):
            ids = np.concatenate([seg_rows[s] for s in job])
            chains[j] = [
                client.submit(
                    track_job, site_dir, method, _specs(plan, job), table.take(ids), ids,
                    key=f"track-{plan.segments[job[0]].key}-n{len(job)}", pure=False,
                    retries=2, priority=n_rows,
                )
            ]  # fmt: skip
            continue
        seg = plan.segments[job[0]]
        rows, t = seg_rows[job[0]], table["t_s"].to_numpy(zero_copy_only=False)
        prev = None
        chains[j] = []
        for w, (lo, hi) in enumerate(seg.windows):
            ids = rows[(t[rows] >= lo) & (t[rows] < hi)]
            prev = client.submit(
                track_window_rows, site_dir, method, seg.seed, prev, table.take(ids), ids,
                (lo, hi), w == len(seg.windows) - 1, (seg.t_first, seg.t_last),
                key=f"track-{seg.key}-w{w}", pure=False, retries=2, priority=n_rows,
            )  # fmt: skip
            chains[j].append(prev)
    return chains


def run_dask(
    plan: Plan,
    table: pa.Table,
    site_dir: str,
    method: str,
    client: Any,
    *,
    shuffle_seed: int | None = None,
    kill_after: int | None = None,
    progress: bool = False,
    on_done: Callable[[int], None] | None = None,
) -> RunResult:
    """Run the plan on ``client``'s cluster: one task per job (:mod:`.fused`).

    Parameters
    ----------
    shuffle_seed : int, optional
        Submit the jobs in an order shuffled by this seed (the results must not change:
        tested).
    kill_after : int, optional
        Once this many tasks have finished, kill one worker's process (tested).
    progress : bool
        Show Dask's progress bar (waits for the end).
    """
    from distributed import as_completed

    from .fused import job_rows

    job_order = list(range(len(plan.jobs)))
    if shuffle_seed is not None:
        random.Random(shuffle_seed).shuffle(job_order)
    rows = job_rows(plan, table)
    chains = _submit_fused(plan, table, rows.segments, (site_dir, method, client), job_order)
    loose = [
        client.submit(geolocate_part, site_dir, *_part_args(plan, table, k),
                      key=plan.parts[k].key, pure=False, retries=2)
        for k in rows.loose_parts
    ]  # fmt: skip
    every = loose + [f for c in chains.values() for f in c]
    if progress:
        from distributed import progress as dask_progress

        dask_progress(every)  # a text bar on stdout, or a widget in a notebook
    notes: dict[str, Any] = {}
    value: dict[str, Any] = {}
    # each result is fetched as its task ends, so the client's unpickling overlaps the run
    for done, (fut, res) in enumerate(as_completed(every, with_results=True), start=1):
        value[fut.key] = res
        if on_done is not None:
            on_done(done)
        if done == kill_after:
            notes["killed_worker"] = _kill_one_worker(client)
    got_loose = [value[f.key] for f in loose]
    got = [[value[f.key] for f in chains[j]] for j in range(len(plan.jobs))]
    geo: list[GeoResult] = list(got_loose)
    tracks: list[list[Any]] = [[] for _ in plan.segments]
    for job, results in zip(plan.jobs, got, strict=True):
        geo.extend(g for g, _ in results)
        if _chained(plan, job):
            tracks[job[0]] = segment_tracks([r for _, r in results])
        else:
            for s, seg_tracks in zip(job, results[0][1], strict=True):
                tracks[s] = seg_tracks
    if "killed_worker" in notes:
        notes["killed_worker_gone"] = (
            notes["killed_worker"] not in client.scheduler_info()["workers"]
        )
    return RunResult(geo, tracks, notes)
