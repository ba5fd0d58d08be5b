"""``demtrack demo`` start-up time, from a truly cold state or a warm one.

Each run launches ``demtrack demo`` as its own process (``python -m demtrack.cli demo``,
what ``uv run --frozen demtrack demo`` runs) on a free port, with

cold
    a new, missing site folder and an empty numba cache of its own (``NUMBA_CACHE_DIR``
    in a temporary folder: the repository's ``__pycache__`` caches, which other processes
    use, are neither read nor wiped), so the demo builds the sample site and compiles
    every kernel;
warm
    the site and the numba cache a previous cold run of this benchmark left.

It polls ``GET /`` from the launch and reads the demo's output, and prints, as seconds
from the launch: each line the demo printed (the sample-site build's steps), the console
URL printed, the console page (``GET /``) answering 200, the page's first API calls
(``/console-config.json``, ``/api/site``, ``/api/sensors``, ``/api/health``, made together
as the page does) all answered, and the rest of what the page loads (orthophoto, relief,
roads, every camera still, tracks), and the replay's first track answered by
``/api/tracks``. With it the load average before and after, and the CPU time the demo and
its children spent until the page's data was loaded.

Run: ``python -m demtrack.bench.cold_start [--runs 2] [--mode cold|warm|both]
[--pythonpath DIR]``. ``--pythonpath`` runs another copy of the package (a tree laid out
as ``DIR/demtrack/{core,server,...}``) for a before/after comparison in the same
conditions; ``--alternate DIR`` runs this tree and that one in turns.
"""

from __future__ import annotations

import argparse
import os
import queue
import re
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["RunResult", "main", "run_demo"]

_CONSOLE = re.compile(r"console\s+(http://\S+)/\?token=(\S+)")


@dataclass
class RunResult:
    """Seconds from the launch of one ``demtrack demo`` process."""

    label: str
    lines: list[tuple[float, str]] = field(default_factory=list)
    url_s: float = float("nan")
    page_s: float = float("nan")
    first_api_s: float = float("nan")
    data_s: float = float("nan")
    track_s: float = float("nan")
    cpu_s: float = float("nan")
    load_before: str = ""
    load_after: str = ""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _loadavg() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def _tree_cpu_s(pid: int) -> float:
    """CPU seconds of a process, its live children and its waited-for children."""
    import psutil

    try:
        p = psutil.Process(pid)
        t = p.cpu_times()
        total = t.user + t.system + t.children_user + t.children_system
        for c in p.children(recursive=True):
            with_c = c.cpu_times()
            total += with_c.user + with_c.system
        return float(total)
    except psutil.Error:
        return float("nan")


def _poll_page(base: str, t0: float, out: dict[str, float], stop: threading.Event) -> None:
    import httpx2 as httpx

    with httpx.Client(base_url=base, timeout=5.0) as c:
        while not stop.is_set():
            try:
                if c.get("/").status_code == 200:
                    out["page"] = time.monotonic() - t0
                    return
            except httpx.HTTPError:
                pass
            stop.wait(0.05)


def _read_lines(proc: subprocess.Popen, t0: float, q: queue.Queue) -> None:
    assert proc.stdout is not None
    for line in proc.stdout:
        q.put((time.monotonic() - t0, line.rstrip("\n")))
    q.put(None)


def _load_page_data(base: str, token: str, t0: float, res: RunResult, pid: int) -> None:
    """The page's requests: the first four together, then everything else it loads.

    Then the CPU time of process ``pid`` so far, and the wait for the first track.
    """
    import httpx2 as httpx

    auth = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=base, timeout=120.0, headers=auth) as c:

        def get(path: str) -> httpx.Response:
            r = c.get(path)
            r.raise_for_status()
            return r

        first = ["/console-config.json", "/api/site", "/api/sensors", "/api/health"]
        with ThreadPoolExecutor(6) as pool:
            answers = list(pool.map(get, first))
            res.first_api_s = time.monotonic() - t0
            sensors = answers[2].json()
            rest = [
                "/api/site/orthophoto.png",
                "/api/site/relief.png?kind=shaded-relief",
                "/api/site/roads.geojson?frame=enu",
                "/api/tracks",
                *(f"/api/sensors/{s['id']}/image" for s in sensors if s.get("image")),
            ]
            list(pool.map(get, rest))
            res.data_s = time.monotonic() - t0
        res.cpu_s = _tree_cpu_s(pid)
        # The replay's first track (geolocation and tracking running), polled for 90 s.
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline:
            if get("/api/tracks").json()["tracks"]:
                res.track_s = time.monotonic() - t0
                break
            time.sleep(0.25)


def run_demo(
    work: Path,
    *,
    label: str,
    pythonpath: Path | None = None,
    timeout_s: float = 300.0,
    autogroup_nice: int | None = None,
    linger_s: float = 0.0,
) -> RunResult:
    """Launch ``demtrack demo`` on ``work/site`` with ``work/numba`` as numba's cache.

    Both are created when missing (a missing site is built: a cold start). ``linger_s``:
    keep the demo running that long after the first track (its background compile ends).
    ``autogroup_nice`` (Linux, root): run the demo in its own session and give its
    scheduler autogroup this nice value (``-15``: other jobs on a shared machine barely
    slow it, as on a dedicated one; within the group the demo's own nice values hold).
    """
    (work / "numba").mkdir(parents=True, exist_ok=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEMTRACK_")}
    env["NUMBA_CACHE_DIR"] = str(work / "numba")
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    cmd = [sys.executable, "-m", "demtrack.cli", "demo", "--site", str(work / "site")]
    cmd += ["--port", str(port), "--viser-port", "0", "--log-level", "warning"]
    res = RunResult(label, load_before=_loadavg())
    t0 = time.monotonic()
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        cwd=work,  # not the repository: its folders would shadow ``--pythonpath``
        start_new_session=autogroup_nice is not None,
    )
    if autogroup_nice is not None:
        Path(f"/proc/{proc.pid}/autogroup").write_text(str(autogroup_nice))
    polled: dict[str, float] = {}
    stop = threading.Event()
    poller = threading.Thread(target=_poll_page, args=(base, t0, polled, stop), daemon=True)
    poller.start()
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_read_lines, args=(proc, t0, lines), daemon=True).start()
    try:
        token = None
        while token is None:
            item = lines.get(timeout=timeout_s)
            if item is None:
                raise RuntimeError("demtrack demo ended early:\n" + _dump(res))
            res.lines.append(item)
            m = _CONSOLE.search(item[1])
            if m:
                res.url_s, token = item[0], m.group(2)
        _load_page_data(base, token, t0, res, proc.pid)
        poller.join(timeout_s)
        res.page_s = polled.get("page", float("nan"))
        time.sleep(linger_s)
    finally:
        stop.set()
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        while True:  # the rest of the output, for the record
            try:
                item = lines.get(timeout=1.0)
            except queue.Empty:
                break
            if item is None:
                break
            res.lines.append(item)
    res.load_after = _loadavg()
    return res


def _dump(res: RunResult) -> str:
    return "\n".join(f"  {t:6.1f} s  {line}" for t, line in res.lines)


def _report(res: RunResult) -> None:
    print(f"\n== {res.label} (load average before {res.load_before}, after {res.load_after})")
    print(_dump(res))
    print(
        f"  console URL printed {res.url_s:.1f} s | GET / 200 {res.page_s:.1f} s | first API"
        f" calls answered {res.first_api_s:.1f} s | page data loaded {res.data_s:.1f} s |"
        f" CPU {res.cpu_s:.1f} s | first track {res.track_s:.1f} s",
        flush=True,
    )


def main(argv: list[str] | None = None) -> int:
    """Run the cold (and/or warm) start-ups and print their figures."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=1, help="runs per mode and tree (default 1)")
    p.add_argument("--mode", choices=["cold", "warm", "both"], default="cold")
    p.add_argument("--pythonpath", type=Path, default=None, help="run another copy's package")
    p.add_argument(
        "--alternate", type=Path, default=None, metavar="DIR", help="also run DIR's, in turns"
    )
    p.add_argument("--timeout", type=float, default=300.0)
    p.add_argument(
        "--settle",
        type=float,
        default=90.0,
        metavar="S",
        help="the run preparing a warm state keeps the demo up S seconds more (default 90),"
        " so its low-priority compile of the fast kernels finishes",
    )
    p.add_argument(
        "--autogroup-nice",
        type=int,
        default=None,
        metavar="N",
        help="give the demo's scheduler autogroup this nice value (-15 shields it from"
        " other jobs on a shared machine; Linux, root)",
    )
    args = p.parse_args(argv)
    trees: list[tuple[str, Path | None]] = [("this tree", args.pythonpath)]
    if args.alternate is not None:
        trees.append((str(args.alternate), args.alternate))
    modes = ["cold", "warm"] if args.mode == "both" else [args.mode]
    results: dict[tuple[str, str], list[RunResult]] = {}
    with tempfile.TemporaryDirectory(prefix="demtrack-cold-") as tmp:
        warm_dirs: dict[str, Path] = {}
        for k in range(args.runs):
            for mode in modes:
                for name, path in trees:
                    if mode == "warm" and name not in warm_dirs:
                        work = Path(tmp) / f"warm-{len(warm_dirs)}"
                        run_demo(
                            work,
                            label="(prepares warm)",
                            pythonpath=path,
                            linger_s=args.settle,
                            autogroup_nice=args.autogroup_nice,
                        )
                        warm_dirs[name] = work
                    n = sum(len(v) for v in results.values())
                    work = warm_dirs[name] if mode == "warm" else Path(tmp) / f"cold-{n}"
                    res = run_demo(
                        work,
                        label=f"{mode} run {k + 1}, {name}",
                        pythonpath=path,
                        timeout_s=args.timeout,
                        autogroup_nice=args.autogroup_nice,
                    )
                    _report(res)
                    results.setdefault((mode, name), []).append(res)
    print("\nsummary (seconds from launch; median, min-max):")
    for (mode, name), rs in results.items():
        cols = []
        for what in ("url_s", "page_s", "first_api_s", "data_s", "cpu_s", "track_s"):
            xs = [getattr(r, what) for r in rs]
            cols.append(f"{what[:-2]} {statistics.median(xs):.1f} ({min(xs):.1f}-{max(xs):.1f})")
        print(f"  {mode:4s} {name}: " + ", ".join(cols))
    return 0


if __name__ == "__main__":
    sys.exit(main())
