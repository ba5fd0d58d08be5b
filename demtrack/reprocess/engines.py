"""Engines that run a :class:`~.plan.Plan`: in this process, or on a Dask cluster.

Both call the same task functions (:mod:`.tasks`) on the same inputs, and each segment's
windows in the same order (a window's task waits for the one before), so their results
are equal. On Dask, geolocation parts run in parallel; each segment is one chain of
window tasks, and segments run in parallel. A worker lost mid-run costs its tasks a
rerun (Dask recomputes what it held, from the inputs the client keeps).
"""

from __future__ import annotations

import os
import random
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import pyarrow as pa

from demtrack.core.errors import InputFileError

from .plan import Plan
from .tasks import GeoResult, WindowResult, geolocate_part, segment_tracks, track_window

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


def run_local(plan: Plan, table: pa.Table, site_dir: str, method: str) -> RunResult:
    """Run every task here, one after another."""
    geo = [geolocate_part(site_dir, *_part_args(plan, table, k)) for k in range(len(plan.parts))]
    tracks = []
    for seg in plan.segments:
        results: list[WindowResult] = []
        prev: WindowResult | None = None
        for w, window in enumerate(seg.windows):
            parts = _window_parts(plan, seg.parts, window)
            last = w == len(seg.windows) - 1
            prev = track_window(
                site_dir, method, seg.seed, prev, [geo[k] for k in parts], window, last
            )
            results.append(prev)
        tracks.append(segment_tracks(results))
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
    """Run the plan on ``client``'s cluster.

    Parameters
    ----------
    shuffle_seed : int, optional
        Submit the geolocation parts, and the segments, in an order shuffled by this seed
        (the results must not change: tested).
    kill_after : int, optional
        Once this many tasks have finished, kill one worker's process (tested).
    progress : bool
        Show Dask's progress bar (waits for the end).
    """
    from distributed import as_completed, wait

    order = list(range(len(plan.parts)))
    seg_order = list(range(len(plan.segments)))
    if shuffle_seed is not None:
        rng = random.Random(shuffle_seed)
        rng.shuffle(order)
        rng.shuffle(seg_order)
    geo: dict[int, Any] = {}
    for k in order:
        rows, ids = _part_args(plan, table, k)
        geo[k] = client.submit(
            geolocate_part, site_dir, rows, ids, key=plan.parts[k].key, pure=False, retries=2
        )
    chains: dict[int, list[Any]] = {}
    for s in seg_order:
        seg = plan.segments[s]
        prev = None
        futs = []
        for w, window in enumerate(seg.windows):
            parts = [geo[k] for k in _window_parts(plan, seg.parts, window)]
            prev = client.submit(
                track_window, site_dir, method, seg.seed, prev, parts, window,
                w == len(seg.windows) - 1, key=f"track-{seg.key}-w{w}", pure=False, retries=2,
            )  # fmt: skip
            futs.append(prev)
        chains[s] = futs
    every = list(geo.values()) + [f for c in chains.values() for f in c]
    if progress:
        from distributed import progress as dask_progress

        dask_progress(every)  # a text bar on stdout, or a widget in a notebook
    notes: dict[str, Any] = {}
    if kill_after is not None:
        done = 0
        for _ in as_completed(every):
            done += 1
            if on_done is not None:
                on_done(done)
            if done == kill_after:
                notes["killed_worker"] = _kill_one_worker(client)
    wait(every)
    geo_results = [geo[k].result() for k in range(len(plan.parts))]
    tracks = [segment_tracks(client.gather(chains[s])) for s in range(len(plan.segments))]
    if "killed_worker" in notes:
        notes["killed_worker_gone"] = (
            notes["killed_worker"] not in client.scheduler_info()["workers"]
        )
    return RunResult(geo_results, tracks, notes)
