"""Archive reprocessing: the local engine's detections/s, Dask at 1, 2, 4 workers.

``demtrack bench reprocess [--site DIR --archive DIR --detections N --workers 1,2,4]``:
the synthetic archive (:mod:`demtrack.reprocess.synth`; made in a temporary folder
unless ``--archive`` and ``--site12`` are given) reprocessed once by the local engine and
once per worker count on a fresh ``LocalCluster``. Every engine is warmed first, untimed
and alike: this process before the local run, and each worker of a cluster
(``client.run``) before its run, geolocate and track the archive's first 2,000 rows
(:func:`demtrack.reprocess.fused.warm_up`: the site loaded, numba's cached kernels, the
tracker's imports); then each run is timed from submission to the last result. Printed
per run: seconds, detections/s, speed-up over one worker, and the share of time in
scheduling overhead, ``1 - (sum of task compute times) / (wall time x workers)`` from
Dask's task stream (so idle workers at the end of a run count as overhead too);
``cpu/core``, the CPU seconds the run's processes got per worker and wall second (1.00:
each worker had a core to itself; below that, other processes took the cores, which a
shared machine shows); and whether every run's content hash equals the local one's.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from .sample_site import site_or_sample

__all__ = ["main"]


def _write(site_dir: str):  # noqa: ANN202  (the reprocess writer of this site)
    from demtrack.reprocess.tasks import site_at
    from demtrack.server.track_export import write_track_file

    return lambda tracks, path: write_track_file(
        site_at(site_dir), tracks, path, batch_geodetic=True
    )


def _timed_dask(site_dir: str, read, plan, method: str, workers: int, out: Path):  # noqa: ANN001, ANN202
    from distributed import get_task_stream

    from demtrack.reprocess.engines import dask_client, run_dask
    from demtrack.reprocess.fused import warm_up
    from demtrack.reprocess.outputs import write_outputs

    t0 = time.perf_counter()
    with dask_client(workers, None) as client:
        t_start = time.perf_counter() - t0
        client.run(warm_up, site_dir, method, _warm_rows(read))  # every worker, untimed
        with get_task_stream(client) as stream:
            cpu0 = client.run(time.process_time)
            t1 = time.perf_counter()
            result = run_dask(plan, read.table, site_dir, method, client)
            wall = time.perf_counter() - t1
            cpu1 = client.run(time.process_time)
        compute = 0.0
        for task in stream.data:
            for part in task.get("startstops", ()):
                if part.get("action") == "compute":
                    compute += float(part["stop"]) - float(part["start"])
    manifest = write_outputs(
        out, result, plan, tracks_name="tracks.geojson", write_tracks=_write(site_dir),
        info={"method": method}, run={},
    )  # fmt: skip
    overhead = max(0.0, 1.0 - compute / (wall * workers)) if wall > 0 else 0.0
    cpu = sum(cpu1[w] - cpu0.get(w, 0.0) for w in cpu1)
    return wall, t_start, overhead, cpu / (wall * workers), manifest["content_hash"]


def _warm_rows(read):  # noqa: ANN001, ANN202  (what every engine runs untimed first)
    return read.table.slice(0, min(2000, read.table.num_rows))


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (``demtrack bench reprocess``); returns the exit status."""
    doc = (__doc__ or "").split("\n")[0]
    p = argparse.ArgumentParser(prog="demtrack bench reprocess", description=doc)
    p.add_argument("--site", type=Path, default=None, help="sample site (default: build one)")
    p.add_argument("--site12", type=Path, default=None, help="the derived 12-camera site")
    p.add_argument("--archive", type=Path, default=None, help="an archive on --site12")
    p.add_argument("--detections", type=int, default=40_000, help="archive size (40000)")
    p.add_argument("--method", default="kalman", help="tracking method (kalman)")
    p.add_argument("--workers", default="1,2,4", help="Dask worker counts (1,2,4)")
    args = p.parse_args(argv)
    counts = [int(w) for w in args.workers.split(",") if w.strip()]
    if args.detections < 1 or not counts or min(counts) < 1:
        p.error("--detections and every --workers count must be positive")
    from demtrack.reprocess.engines import run_local
    from demtrack.reprocess.outputs import write_outputs
    from demtrack.reprocess.run import ReprocessSettings, plan_run
    from demtrack.reprocess.synth import make_camera_site, synth_archive

    with tempfile.TemporaryDirectory(prefix="demtrack-reprocess-") as tmp:
        tmpd = Path(tmp)
        if args.archive is None or args.site12 is None:
            base = site_or_sample(args.site, tmpd, announce=True)
            site12 = make_camera_site(base, tmpd / "site12", 12)
            archive = tmpd / "archive"
            got = synth_archive(site12, archive, args.detections)
            print(f"archive: {got['detections']} detections, 12 cameras ({got['copies']} copies)")
        else:
            site12, archive = args.site12, args.archive
        site_dir = str(site12)
        t0 = time.perf_counter()
        read, plan = plan_run(site_dir, str(archive), ReprocessSettings(args.method))
        n = read.table.num_rows
        print(
            f"plan: {len(plan.groups)} sensor groups, {len(plan.segments)} segments,"
            f" {len(plan.parts)} geolocation parts ({time.perf_counter() - t0:.1f} s)"
        )
        from demtrack.reprocess.fused import warm_up

        warm_up(site_dir, args.method, _warm_rows(read))  # as each Dask worker does
        c1, t1 = time.process_time(), time.perf_counter()
        local = run_local(plan, read.table, site_dir, args.method)
        t_local = time.perf_counter() - t1
        share_local = (time.process_time() - c1) / t_local
        ref = write_outputs(
            tmpd / "local", local, plan, tracks_name="tracks.geojson",
            write_tracks=_write(site_dir), info={"method": args.method}, run={},
        )["content_hash"]  # fmt: skip
        print(f"method {args.method}; the machine may be shared: figures are noisy, ratios")
        print("engine     workers   seconds   det/s  speed-up  overhead  cpu/core  hash")
        print(
            f"local            -  {t_local:8.1f}  {n / t_local:6.0f}"
            f"         -         -  {share_local:7.2f}  {ref[:12]}"
        )
        base_wall = None
        same = True
        for w in counts:
            wall, t_start, overhead, share, digest = _timed_dask(
                site_dir, read, plan, args.method, w, tmpd / f"dask{w}"
            )
            base_wall = wall if base_wall is None else base_wall
            same &= digest == ref
            print(
                f"dask       {w:7d}  {wall:8.1f}  {n / wall:6.0f}  {base_wall / wall:7.2f}x"
                f"  {100 * overhead:7.1f}%  {share:7.2f}  {digest[:12]}"
                f"  (cluster start {t_start:.1f} s)"
            )
        print(f"every content hash equals the local run's: {'yes' if same else 'NO'}")
    return 0 if same else 1
