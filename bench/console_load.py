"""Console page load time on loopback (Chromium, headless) with the sample site.

Starts ``demtrack serve`` on a free port with a built sample site, ingests a scenario so
the page has tracks to load, then loads the console ``--runs`` times in fresh browser
contexts (cold HTTP cache each time) and prints the time from navigation start (the
browser's clock) to the page's ``data-ready`` mark (site, sensors, orthophoto, relief,
roads, camera stills, tracks and the newest boxes loaded; the stream opening), median and
worst. Target: under 2 s.

Run: ``python -m demtrack.bench.console_load [--site DIR] [--runs 5]``. Needs
``npm ci --prefix web`` and Debian's Chromium (``/usr/bin/chromium``).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from .console_harness import ServeProcess, launch_chromium
from .sample_site import site_or_sample

__all__ = ["main"]

_TOKEN = "bench-console-token"


def _ingest(site: Path, server: ServeProcess, scenario: str) -> int:
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.scenarios import make_scenario

    dets = make_scenario(load_site(site), scenario).detections
    recs = [
        {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": d.score}
        for d in dets
    ]
    with server.client() as c:
        for i in range(0, len(recs), 500):
            c.post("/api/detections", json={"detections": recs[i : i + 500]}).raise_for_status()
        return len(c.get("/api/tracks").json()["tracks"])


def main(argv: list[str] | None = None) -> int:
    """Measure and print the console's load time."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--site", type=Path, default=None, help="built site (default: build one)")
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--scenario", default="vehicle-run")
    args = p.parse_args(argv)
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        site = site_or_sample(args.site, Path(tmp))
        server = ServeProcess(site, Path(tmp) / "bench.sqlite3", _TOKEN).start()
        try:
            n_tracks = _ingest(site, server, args.scenario)
            url = f"{server.url}/?token={_TOKEN}"
            times = []
            with sync_playwright() as pw:
                browser = launch_chromium(pw)
                for k in range(args.runs + 1):  # the first run warms the server's caches
                    ctx = browser.new_context(viewport={"width": 1280, "height": 800})
                    page = ctx.new_page()
                    page.goto(url)
                    page.wait_for_selector("body[data-ready='1']", timeout=120_000)
                    dt = page.evaluate("window.demtrack.ui.readyMs") / 1000.0
                    if k:
                        times.append(dt)
                    else:
                        print(f"first load (server renders and caches the images): {dt:.2f} s")
                    ctx.close()
                browser.close()
        finally:
            server.stop()
    print(
        f"console load on loopback, {n_tracks} tracks ({args.scenario}), {args.runs} runs:"
        f" median {statistics.median(times):.2f} s, worst {max(times):.2f} s (target < 2 s)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
