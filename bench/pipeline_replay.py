"""The console soak's server work in-process: CPU per detection along the scenario.

The soak (:mod:`.console_soak`) measures the whole console (uvicorn, the stream, the page's
polls, Chromium on the same two cores) and its pace swings with the machine. This replays
the same detections (the three sample-site scenarios, ``--copies`` staggered copies each, the
cameras at ``--rate-hz``, looping: what ``demtrack serve --replay`` makes) straight into a
:class:`~demtrack.server.ingest.pipeline.Pipeline` over a fresh SQLite file, ``--coalesce`` replay
frames per batch, with the server's garbage-collector settings
(:func:`demtrack.server.gc_tuning.tune_gc_for_serving`), and no HTTP, stream or browser. It
prints, every ``--every`` s of scenario time, the CPU per detection, the share of it spent in
the cyclic garbage collector and in the store's write transactions, and the objects the
collector tracks; then the rate one core sustains against the rate 10x needs. The workload
is the same in every run, so two versions of the code compare in a minute or two.

Run: ``python -m demtrack.bench.pipeline_replay [--site DIR] [--duration 600] [--copies 4]
[--rate-hz 10] [--coalesce 60] [--every 100]`` (``demtrack bench pipeline``).
"""

from __future__ import annotations

import argparse
import gc
import itertools
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .sample_site import SOAK_SCENARIOS, site_or_sample

__all__ = ["CpuMeter", "main", "replay_in_process"]


class CpuMeter:
    """Process CPU, cyclic-GC wall time and store-transaction CPU since :meth:`reset`."""

    def __init__(self) -> None:
        self._gc_start = 0.0
        self.gc_s = 0.0
        self.tx_s = 0.0
        self.cpu0 = time.process_time()

    def reset(self) -> None:
        """Start counting again from now."""
        self.gc_s = self.tx_s = 0.0
        self.cpu0 = time.process_time()

    @property
    def cpu_s(self) -> float:
        """Process CPU time (s) since the last reset."""
        return time.process_time() - self.cpu0

    def on_gc(self, phase: str, info: dict[str, Any]) -> None:
        """A ``gc.callbacks`` entry: adds each collection's duration."""
        if phase == "start":
            self._gc_start = time.perf_counter()
        else:
            self.gc_s += time.perf_counter() - self._gc_start

    @contextmanager
    def watching(self, store: Any) -> Iterator[None]:
        """Count the collector's time and ``store``'s write transactions while inside."""
        tx = store._tx

        def timed_tx(fn: Callable[..., Any], **kw: Any) -> Any:
            c0 = time.thread_time()
            try:
                return tx(fn, **kw)
            finally:
                self.tx_s += time.thread_time() - c0

        gc.callbacks.append(self.on_gc)
        store._tx = timed_tx
        try:
            yield
        finally:
            gc.callbacks.remove(self.on_gc)
            del store._tx


def replay_in_process(args: argparse.Namespace, site_dir: Path, db: Path) -> list[dict[str, Any]]:
    """Replay into a pipeline; one row per ``args.every`` s of scenario time."""
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS
    from demtrack.server.gc_tuning import tune_gc_for_serving
    from demtrack.server.ingest.pipeline import Pipeline, pipeline_options
    from demtrack.server.replay import scenario_stream
    from demtrack.server.settings import Settings
    from demtrack.server.store.database import Store

    settings = Settings(site=site_dir, db_path=db)
    site = load_site(site_dir)
    store = Store(db)
    pipeline = Pipeline(
        site, store, settings.tracker_method, lambda _: None, **pipeline_options(settings)
    )
    pipeline.start()
    frames = iter(
        scenario_stream(
            site,
            list(SOAK_SCENARIOS),
            0.0,
            source=SAMPLE_SCENARIOS,
            loop=True,
            copies=args.copies,
            rate_hz=args.rate_hz,
        )
    )
    gc.collect()
    thresholds = gc.get_threshold()
    tune_gc_for_serving()
    meter = CpuMeter()
    rows: list[dict[str, Any]] = []
    t_first = t_mark = None
    n = 0
    try:
        with meter.watching(store):
            while True:
                batch = list(itertools.islice(frames, args.coalesce))
                if not batch:
                    break
                t = batch[-1].t_s
                if t_first is None:
                    t_first = t_mark = batch[0].t_s
                    meter.reset()
                records = [r for f in batch for r in f.records]
                pipeline.ingest(records)
                n += len(records)
                if t - t_mark >= args.every:
                    rows.append(
                        {
                            "t_s": t - t_first,
                            "detections": n,
                            "det_per_s": n / (t - t_mark),
                            "cpu_us": 1e6 * meter.cpu_s / n,
                            "gc_frac": meter.gc_s / meter.cpu_s,
                            "tx_frac": meter.tx_s / meter.cpu_s,
                            "objects": len(gc.get_objects()),
                        }
                    )
                    print(_row(rows[-1]), flush=True)
                    meter.reset()
                    n, t_mark = 0, t
                if t - t_first >= args.duration:
                    break
    finally:
        store.close()
        gc.set_threshold(*thresholds)  # as they were (a test process goes on)
        gc.unfreeze()
    return rows


def _row(r: dict[str, Any]) -> str:
    return (
        f"{r['t_s']:7.0f} {r['detections']:8d} {r['cpu_us']:8.1f} {100 * r['gc_frac']:5.1f}"
        f" {100 * r['tx_frac']:5.1f} {r['objects']:9d}"
    )


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (``demtrack bench pipeline``); returns the exit status."""
    doc = (__doc__ or "").split("\n")[0]
    p = argparse.ArgumentParser(prog="demtrack bench pipeline", description=doc)
    p.add_argument("--site", type=Path, default=None, help="built site (default: build one)")
    p.add_argument("--duration", type=float, default=600.0, help="scenario seconds (600)")
    p.add_argument("--copies", type=int, default=4, help="copies of each scenario (4)")
    p.add_argument("--rate-hz", type=float, default=10.0, help="camera frame rate (10)")
    p.add_argument(
        "--coalesce",
        type=int,
        default=60,
        help="replay frames per batch (60: what the server's 0.1 s batches hold at 10x)",
    )
    p.add_argument("--every", type=float, default=100.0, help="scenario seconds per row (100)")
    p.add_argument("--speed", type=float, default=10.0, help="the replay speed to compare with")
    args = p.parse_args(argv)
    if args.duration <= 0 or args.every <= 0 or args.coalesce < 1 or args.copies < 1:
        p.error("--duration, --every, --coalesce and --copies must be positive")
    with tempfile.TemporaryDirectory(prefix="demtrack-pipeline-") as tmp:
        site_dir = site_or_sample(args.site, Path(tmp))
        print(
            f"pipeline replay: {', '.join(SOAK_SCENARIOS)} x {args.copies} copies, "
            f"{args.rate_hz:g} Hz cameras, {args.coalesce} frames per batch, in-process"
        )
        print(" scen s     det   us/det  gc %  tx % gc objects")
        rows = replay_in_process(args, site_dir, Path(tmp) / "pipeline.sqlite3")
    steady = rows[1:]  # the first row holds the copies' staggered start
    if not steady:
        print("too short: give --duration at least two --every")
        return 1
    n = sum(r["detections"] for r in steady)
    us = sum(r["cpu_us"] * r["detections"] for r in steady) / n
    need = args.speed * sum(r["det_per_s"] * r["detections"] for r in steady) / n
    print(
        f"after the first row: {us:.1f} us of CPU per detection, one core sustains"
        f" {1e6 / us:,.0f} det/s;"
        f" {args.speed:g}x needs {need:,.0f} det/s (headroom {1e6 / us / need:.2f}x before"
        " HTTP, the stream, the page's polls and a browser on the same cores)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
