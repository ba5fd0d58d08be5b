"""Console soak: a long replay at 10x with about 20 live tracks, watched in headless Chromium.

Starts ``demtrack serve`` on a free port with a built sample site, replaying the three
sample-site scenarios together, each as ``--copies`` copies staggered over its period (4
copies keep about 20 tracks alive), at ``--speed`` times real time with the cameras at
``--rate-hz`` for ``--duration`` seconds of scenario time. The console is opened in
headless Chromium before the first frame, so everything it shows arrives on the stream.
Every ``--every`` wall seconds it samples:

- the page: JS heap after a forced GC and DOM nodes (CDP ``Performance.getMetrics``),
  animation frames and map redraws per second and main-thread script time since the last
  sample, the CPU of Chromium and the Playwright driver (psutil, this process's other
  children), the
  features of the live-tracks layer (trails and head dots), the store's sizes (tracks,
  points, fixes, events), the stream's received messages and sequence gaps, WebSocket
  (re)connections;
- the server: resident memory and CPU time (psutil), ``/api/status`` (detections, clients
  dropped for falling behind), the tracks with a point in the newest 2 s (``/api/tracks``);
- the pace: the newest scenario time the page has seen against ``speed`` x the wall time
  since its first one (the lag), and the detection rate that pace needs and gets.

It prints a table over time and a verdict: heap, DOM and server-memory growth over the
second half (MB per scenario hour, from a least-squares line), sequence gaps and
reconnections, the largest lag and the pace reached.

Run: ``python -m demtrack.bench.console_soak [--site DIR] [--duration 3600] [--speed 10]
[--copies 4] [--rate-hz 10] [--every 20] [--no-events]`` (``demtrack bench console-soak``). Needs
``npm ci --prefix web`` and Debian's Chromium (``/usr/bin/chromium``).
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .console_harness import ServeProcess, launch_chromium
from .sample_site import SOAK_SCENARIOS, site_or_sample

__all__ = [
    "PROBE_INIT_JS",
    "SCENARIOS",
    "Sample",
    "cdp_metrics",
    "main",
    "page_state",
    "replay_server",
    "slope",
]

SCENARIOS = SOAK_SCENARIOS
_TOKEN = "bench-console-soak-token"

#: Installed before the page's own scripts: counts animation frames and long tasks.
PROBE_INIT_JS = """
window.__soak = {frames: 0, longTasks: 0, longMs: 0};
(function tick() { window.__soak.frames += 1; requestAnimationFrame(tick); })();
try {
  new PerformanceObserver((list) => {
    for (const e of list.getEntries()) {
      window.__soak.longTasks += 1;
      window.__soak.longMs += e.duration;
    }
  }).observe({entryTypes: ["longtask"]});
} catch (_) { /* no long-task timing here */ }
"""

_STATE_JS = """async () => {
  const d = window.demtrack;
  const { LIMITS } = await import("/console/store.mjs");
  const s = d.store;
  let live = 0, points = 0, maxPoints = 0, fixes = 0, maxFixes = 0;
  for (const t of s.tracks.values()) {
    if (t.live) live += 1;
    points += t.points.length;
    maxPoints = Math.max(maxPoints, t.points.length);
  }
  for (const l of s.fixes.values()) { fixes += l.length; maxFixes = Math.max(maxFixes, l.length); }
  const feats = d.map ? d.map.trails.getSource().getFeatures() : [];
  const st = d.stream;
  return {
    tracks: s.tracks.size, live, points, maxPoints, fixes, maxFixes,
    events: s.events.length, detToTrack: s.detToTrack.size, limits: LIMITS,
    trails: feats.filter((f) => f.get("kind") === "trail").length,
    heads: feats.filter((f) => f.get("kind") === "head").length,
    synopsis: d.map ? d.map.synopsis.getSource().getFeatures().length : 0,
    received: st ? st.nReceived : 0, gaps: st ? st.nGaps : 0, lastSeq: st ? st.lastSeq : null,
    tMax: s.tMax, shownT: d.timeline.now(), following: d.timeline.live,
    counts: document.querySelector("#counts")?.textContent || "",
    nTracks: document.querySelector("#n-tracks")?.textContent || "",
    conn: document.querySelector("#conn")?.dataset.state || "",
    frames: window.__soak ? window.__soak.frames : 0,
    redraws: d.ui ? d.ui.redraws : 0,
    longTasks: window.__soak ? window.__soak.longTasks : 0,
    longMs: window.__soak ? window.__soak.longMs : 0,
  };
}"""


@dataclass(frozen=True)
class Sample:
    """One sample of the soak (wall time from the first replayed data).

    Times in seconds (``t_s``: the newest scenario time the page has seen, from the
    replay's start), memory in MB (10^6 bytes), rates per second of wall time.
    """

    wall_s: float
    t_s: float
    pace: float
    lag_s: float
    heap_mb: float
    nodes: int
    fps: float
    redraws_per_s: float
    script_frac: float
    long_tasks: int
    trails: int
    heads: int
    tracks: int
    live: int
    points: int
    fixes: int
    events: int
    received: int
    gaps: int
    ws_opened: int
    api_recent: int
    api_live: int
    detections: int
    det_per_s: float
    ws_dropped: int
    server_rss_mb: float
    server_cpu_frac: float
    server_wait_frac: float
    browser_cpu_frac: float


def page_state(page: Any) -> dict[str, Any]:
    """The console's state: store sizes and limits, stream counters, track-layer features."""
    return dict(page.evaluate(_STATE_JS))


def cdp_metrics(cdp: Any, *, gc: bool = True) -> dict[str, float]:
    """Chrome's ``Performance.getMetrics`` by name (after a forced GC when ``gc``)."""
    if gc:
        cdp.send("HeapProfiler.collectGarbage")
    return {m["name"]: float(m["value"]) for m in cdp.send("Performance.getMetrics")["metrics"]}


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of ``ys`` over ``xs`` (NaN with fewer than two distinct xs)."""
    n = len(xs)
    if n < 2:
        return math.nan
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    if sxx == 0:
        return math.nan
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sxx


def _run_queue_wait_s(pid: int) -> float:
    """Seconds the process's threads have waited for a CPU (``/proc``, Linux schedstat)."""
    total = 0
    for stat in Path(f"/proc/{pid}/task").glob("*/schedstat"):
        try:
            total += int(stat.read_text().split()[1])
        except (OSError, IndexError, ValueError):  # a thread that just ended
            continue
    return total / 1e9


def _server_usage(pid: int) -> tuple[float, float, float]:
    """Resident memory (MB), CPU time (s) and run-queue wait (s) of a process."""
    wait = _run_queue_wait_s(pid)
    try:
        import psutil
    except ImportError:  # /proc for RSS; no CPU time then
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024 / 1e6, math.nan, wait
        return math.nan, math.nan, wait
    proc = psutil.Process(pid)
    cpu = proc.cpu_times()
    return proc.memory_info().rss / 1e6, cpu.user + cpu.system, wait


def _browser_cpu_s(server_pid: int) -> float:
    """CPU time (s) of this process's descendants but the server: Playwright and Chromium."""
    try:
        import psutil
    except ImportError:
        return math.nan
    total = 0.0
    for child in psutil.Process().children(recursive=True):
        try:
            if child.pid == server_pid or server_pid in {p.pid for p in child.parents()}:
                continue
            cpu = child.cpu_times()
            total += cpu.user + cpu.system
        except psutil.Error:  # a process that just ended
            continue
    return total


def replay_server(
    site: Path,
    db: Path,
    token: str,
    *,
    speed: float,
    copies: int,
    rate_hz: float,
    duration_s: float,
    scenarios: tuple[str, ...] = SCENARIOS,
    events: bool = True,
    start: str | None = None,
) -> ServeProcess:
    """A (not yet started) ``demtrack serve`` replaying ``scenarios`` for ``duration_s``.

    ``events=False`` turns the live activity detectors off (``DEMTRACK_EVENTS``);
    ``start``: the replay's first UTC time (ISO 8601; default now, as ``serve`` has it).
    """
    args = [a for name in scenarios for a in ("--replay", name)] + ["--speed", str(speed)]
    if start is not None:
        args += ["--start", start]
    env = {
        "DEMTRACK_REPLAY_COPIES": str(copies),
        "DEMTRACK_REPLAY_RATE_HZ": str(rate_hz),
        "DEMTRACK_REPLAY_DURATION_S": str(duration_s),
        "DEMTRACK_EVENTS": "true" if events else "false",
    }
    return ServeProcess(site, db, token, args=args, env=env)


def _soak(args: argparse.Namespace, site: Path, tmp: Path) -> tuple[list[Sample], dict]:
    from playwright.sync_api import sync_playwright

    start_s = float(math.floor(time.time()))  # the replay's scenario time 0 (UTC)
    server = replay_server(
        site,
        tmp / "soak.sqlite3",
        _TOKEN,
        speed=args.speed,
        copies=args.copies,
        rate_hz=args.rate_hz,
        duration_s=args.duration,
        events=not args.no_events,
        start=datetime.fromtimestamp(start_s, UTC).isoformat().replace("+00:00", "Z"),
    ).start()
    samples: list[Sample] = []
    final: dict[str, Any] = {}
    opened: list[str] = []
    errors: list[str] = []
    try:
        with sync_playwright() as pw, server.client() as api:
            browser = launch_chromium(pw)
            ctx = browser.new_context(viewport={"width": 1280, "height": 800})
            ctx.add_init_script(PROBE_INIT_JS)
            page = ctx.new_page()
            page.on("websocket", lambda ws: opened.append(ws.url))
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{server.url}/?token={_TOKEN}")
            page.wait_for_selector("body[data-ready='1']", timeout=300_000)
            cdp = ctx.new_cdp_session(page)
            cdp.send("Performance.enable")
            # The replay generates its scenarios first (a few seconds each): wait for data.
            deadline = time.monotonic() + 600
            while page_state(page)["tMax"] is None:
                if time.monotonic() > deadline:
                    raise RuntimeError("no replayed data reached the page in 10 minutes")
                time.sleep(0.25)
            w0, st = time.monotonic(), page_state(page)
            t0 = float(st["tMax"])
            max_wall = args.max_wall or 1.5 * args.duration / args.speed + 120
            prev: dict[str, float] | None = None
            while True:
                m = cdp_metrics(cdp)
                st = page_state(page)
                wall = time.monotonic() - w0
                rss, cpu, waited = _server_usage(server.pid)
                browser_cpu = _browser_cpu_s(server.pid)
                status = api.get("/api/status").json()["counts"]
                t_rel = float(st["tMax"]) - t0
                recent = api.get("/api/tracks", params={"t_from": float(st["tMax"]) - 2.0})
                recent_tracks = recent.json()["tracks"]
                cur = {
                    "wall": wall,
                    "frames": st["frames"],
                    "redraws": st["redraws"],
                    "browser_cpu": browser_cpu,
                    "script": m.get("ScriptDuration", 0.0),
                    "cpu": cpu,
                    "wait": waited,
                    "det": float(status["detections"]),
                    "t": t_rel,
                }
                d_wall = wall - prev["wall"] if prev else 0.0
                samples.append(
                    Sample(
                        wall_s=wall,
                        t_s=t_rel,
                        pace=(t_rel - prev["t"]) / d_wall if prev else math.nan,
                        lag_s=args.speed * wall - t_rel,
                        heap_mb=m["JSHeapUsedSize"] / 1e6,
                        nodes=int(m["Nodes"]),
                        fps=(st["frames"] - prev["frames"]) / d_wall if prev else math.nan,
                        redraws_per_s=(st["redraws"] - prev["redraws"]) / d_wall
                        if prev
                        else math.nan,
                        script_frac=(cur["script"] - prev["script"]) / d_wall if prev else math.nan,
                        long_tasks=int(st["longTasks"]),
                        trails=st["trails"],
                        heads=st["heads"],
                        tracks=st["tracks"],
                        live=st["live"],
                        points=st["points"],
                        fixes=st["fixes"],
                        events=st["events"],
                        received=st["received"],
                        gaps=st["gaps"],
                        ws_opened=len(opened),
                        api_recent=len(recent_tracks),
                        api_live=sum(1 for t in recent_tracks if t.get("live")),
                        detections=int(status["detections"]),
                        det_per_s=(cur["det"] - prev["det"]) / d_wall if prev else math.nan,
                        ws_dropped=int(status.get("ws_dropped", 0)),
                        server_rss_mb=rss,
                        server_cpu_frac=(cpu - prev["cpu"]) / d_wall if prev else math.nan,
                        # a thread that ended takes its wait along: NaN rather than < 0
                        server_wait_frac=(waited - prev["wait"]) / d_wall
                        if prev and waited >= prev["wait"]
                        else math.nan,
                        browser_cpu_frac=(browser_cpu - prev["browser_cpu"]) / d_wall
                        if prev
                        else math.nan,
                    )
                )
                print(_row(samples[-1]), flush=True)
                prev = cur
                # A fresh store: the page's times are the replay's, stamped from start_s.
                t_abs, end = float(st["tMax"]), start_s + args.duration - 1.0
                if t_abs >= end or wall >= max_wall or _replay_ended(samples):
                    break
                # Watch for the end only when it may come before the next sample.
                watch = t_abs + args.speed * args.every >= end
                _wait_for_sample(page, w0 + wall + args.every, end if watch else None)
            final = {**page_state(page), "errors": errors[:20], "n_errors": len(errors)}
            if args.screenshot:
                args.screenshot.parent.mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(args.screenshot))
            ctx.close()
            browser.close()
    finally:
        server.stop()
    return samples, final


def _wait_for_sample(page: Any, until: float, end_t_s: float | None) -> None:
    """Sleep until wall time ``until``, or until the page has data of ``end_t_s``.

    The end's sample is then taken when the scenario ends, not up to ``--every`` s after
    (which would lower the pace). Polls only the page's newest time (the full sample
    forces a garbage collection in the page), and only with an ``end_t_s``.
    """
    while (left := until - time.monotonic()) > 0:
        if end_t_s is None:
            time.sleep(left)
            return
        time.sleep(min(left, 0.5))
        t_max = page.evaluate("() => window.demtrack.store.tMax")
        if t_max is not None and float(t_max) >= end_t_s:
            return


def _replay_ended(samples: list[Sample], quiet: int = 2) -> bool:
    """True once no detection arrived for ``quiet`` samples: the replay is over.

    Its scenario time starts before the page's first data, so ``t_s`` stops short of
    ``--duration``; the idle samples are dropped, so they do not dilute the pace and the
    averages.
    """
    if len(samples) <= quiet or samples[-1].detections == 0:
        return False
    if any(s.detections != samples[-1].detections for s in samples[-quiet - 1 :]):
        return False
    del samples[len(samples) - quiet :]
    return True


_HEAD = (
    f"{'wall s':>7} {'scen s':>7} {'pace':>5} {'lag s':>6} {'det/s':>6} {'api':>4} {'live':>4}"
    f" {'heads':>5} {'store':>5} {'points':>7} {'fixes':>5} {'heap MB':>7} {'nodes':>6}"
    f" {'fps':>5} {'rdr/s':>5} {'js %':>5} {'brw %':>5} {'srv MB':>7} {'srv %':>5} {'wait %':>6}"
    f" {'gaps':>4} {'ws':>3}"
)


def _row(s: Sample) -> str:
    return (
        f"{s.wall_s:7.0f} {s.t_s:7.0f} {s.pace:5.1f} {s.lag_s:6.0f} {s.det_per_s:6.0f}"
        f" {s.api_recent:4d} {s.api_live:4d} {s.heads:5d} {s.tracks:5d} {s.points:7d}"
        f" {s.fixes:5d} {s.heap_mb:7.1f} {s.nodes:6d} {s.fps:5.1f} {s.redraws_per_s:5.1f}"
        f" {100 * s.script_frac:5.1f} {100 * s.browser_cpu_frac:5.0f}"
        f" {s.server_rss_mb:7.1f} {100 * s.server_cpu_frac:5.0f} {100 * s.server_wait_frac:6.0f}"
        f" {s.gaps:4d} {s.ws_opened:3d}"
    )


def verdict(samples: list[Sample], final: dict[str, Any], args: argparse.Namespace) -> list[str]:
    """The summary lines: growth over the second half, gaps, pace."""
    last = samples[-1]
    half = [s for s in samples if s.wall_s >= last.wall_s / 2]
    hours = [s.t_s / 3600 for s in half]

    def per_hour(values: list[float]) -> float:
        return slope(hours, values)

    pace = last.t_s / last.wall_s if last.wall_s > 0 else math.nan
    # The page's first data comes a little after the replay's start, so the pace stays just
    # under the target even when nothing falls behind; a lag that does not grow shows that.
    lag_growth = per_hour([s.lag_s for s in half])
    offered = last.detections / last.t_s if last.t_s > 0 else math.nan
    mean = lambda xs: sum(xs) / len(xs) if xs else math.nan  # noqa: E731
    nanmean = lambda xs: mean([x for x in xs if not math.isnan(x)])  # noqa: E731
    fps = [s.fps for s in samples if not math.isnan(s.fps)]
    limits = final.get("limits", {})

    def cpu_ms_per_detection(part: list[Sample]) -> float:
        # server CPU per detection: flat when the cost does not grow with the history
        pairs = [(a, b) for a, b in zip(samples, samples[1:], strict=False) if b in part]
        cpu = sum(b.server_cpu_frac * (b.wall_s - a.wall_s) for a, b in pairs)
        det = sum(b.det_per_s * (b.wall_s - a.wall_s) for a, b in pairs)
        return 1000 * cpu / det if det > 0 else math.nan

    first = [s for s in samples if s.wall_s < last.wall_s / 2]
    caps_ok = (
        final.get("maxPoints", 0) <= limits.get("pointsPerTrack", math.inf)
        and final.get("tracks", 0) <= limits.get("tracks", math.inf)
        and final.get("points", 0) <= limits.get("totalPoints", math.inf)
        and final.get("maxFixes", 0) <= limits.get("fixesPerSensor", math.inf)
        and final.get("events", 0) <= limits.get("events", math.inf)
    )
    return [
        f"replayed {last.t_s:.0f} s of scenario time in {last.wall_s:.0f} s wall: pace"
        f" {pace:.2f}x (target {args.speed:g}x), largest lag {max(s.lag_s for s in samples):.1f}"
        f" s of scenario time, lag growth over the second half {lag_growth:+.1f} s per scenario"
        " hour (about 0: the server keeps the replay's pace)",
        f"detections: {offered:.0f} per scenario s at {args.rate_hz:g} Hz, so {args.speed:g}x"
        f" needs {offered * args.speed:.0f}/s; ingested {last.detections / last.wall_s:.0f}/s;"
        f" the server used {100 * mean([s.server_cpu_frac for s in samples[1:]]):.0f} % of a"
        f" core and its threads waited {100 * nanmean([s.server_wait_frac for s in samples]):.0f}"
        " % of the time for a CPU; server CPU per detection: first half"
        f" {1000 * cpu_ms_per_detection(first):.0f} us, second half"
        f" {1000 * cpu_ms_per_detection(half):.0f} us",
        "tracks with a point in the newest 2 s (API): mean"
        f" {mean([s.api_recent for s in half]):.1f}, live {mean([s.api_live for s in half]):.1f};"
        " dots on the map: mean"
        f" {mean([s.heads for s in half]):.1f} (second half)",
        f"stream: {last.received} messages, {last.gaps} sequence gaps, {last.ws_opened - 1}"
        f" reconnections, {last.ws_dropped} clients dropped by the server;"
        f" page errors: {final.get('n_errors', 0)}",
        f"growth over the second half, per scenario hour: JS heap"
        f" {per_hour([s.heap_mb for s in half]):+.1f} MB (now {last.heap_mb:.1f} MB), DOM nodes"
        f" {per_hour([float(s.nodes) for s in half]):+.0f} (now {last.nodes}), server RSS"
        f" {per_hour([s.server_rss_mb for s in half]):+.1f} MB (now {last.server_rss_mb:.0f} MB)",
        f"store: {final.get('tracks')} tracks, {final.get('points')} points (longest"
        f" {final.get('maxPoints')}), {final.get('fixes')} fixes, {final.get('events')} events:"
        f" {'within' if caps_ok else 'OVER'} the caps {json.dumps(limits)}",
        f"page: {mean(fps):.1f} frames/s mean, {min(fps, default=math.nan):.1f} worst interval;"
        f" {nanmean([s.redraws_per_s for s in samples]):.1f} map redraws/s;"
        f" {last.long_tasks} long tasks (> 50 ms); main-thread script"
        f" {100 * mean([s.script_frac for s in samples[1:]]):.0f} % of wall time; Chromium and"
        f" Playwright {100 * nanmean([s.browser_cpu_frac for s in samples]):.0f} % of a core",
    ]


def main(argv: list[str] | None = None) -> int:
    """Run the soak and print the table and the verdict."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--site", type=Path, default=None, help="built site (default: build one)")
    p.add_argument("--duration", type=float, default=3600.0, help="scenario seconds (3600)")
    p.add_argument("--speed", type=float, default=10.0, help="replay speed (10)")
    p.add_argument("--copies", type=int, default=4, help="copies of each scenario (4)")
    p.add_argument("--rate-hz", type=float, default=10.0, help="camera frame rate (10)")
    p.add_argument("--every", type=float, default=20.0, help="wall seconds between samples")
    p.add_argument(
        "--no-events", action="store_true", help="live activity detectors off on the server"
    )
    p.add_argument("--max-wall", type=float, default=None, help="stop after this many wall seconds")
    p.add_argument("--json", type=Path, default=None, help="write the samples here")
    p.add_argument("--screenshot", type=Path, default=None, help="save the page here at the end")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        site = site_or_sample(args.site, Path(tmp))
        print(
            f"console soak: {', '.join(SCENARIOS)} x {args.copies} copies, {args.rate_hz:g} Hz"
            f" cameras, {args.duration:g} s of scenario time at {args.speed:g}x"
            + (", live events off" if args.no_events else "")
        )
        print(_HEAD, flush=True)
        samples, final = _soak(args, Path(site), Path(tmp))
    lines = verdict(samples, final, args)
    print("\n".join(lines))
    if args.json:
        args.json.write_text(
            json.dumps({"samples": [asdict(s) for s in samples], "final": final}, indent=1)
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
