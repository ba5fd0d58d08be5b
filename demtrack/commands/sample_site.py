"""``demtrack sample-site`` and ``demtrack demo``.

``demtrack demo`` is the live console: it builds the sample site if it is missing, starts
the server (uvicorn, in this process) with scenarios replaying live into the ingest path
and the viser 3D scene, and prints the console, API-docs and 3D-view URLs once the first
page can be served. ``demtrack demo --walkthrough`` prints the older text walk-through
(one geolocation from each camera) instead.
"""

from __future__ import annotations

import argparse
import functools
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .choices import MANIFEST
from .common import DEFAULT_SITE, port
from .geolocate import print_geolocation
from .serve import add_live_arguments, live_overrides, scenario_source, serve_app

if TYPE_CHECKING:
    from demtrack.core.geolocation.geolocate import Geolocator
    from demtrack.core.site.folder import Sensor, Site

__all__ = ["DEMO_SCENARIOS", "ensure_sample_site", "register"]

#: What ``demtrack demo`` replays by default: a car on the roads, people on the field.
#: The demo's default replay: the paper's vehicle run, pedestrians, and one case of each
#: activity detector (loitering, rendezvous, convoy), so every detector shows in the first loop.
DEMO_SCENARIOS = ["vehicle-run", "pedestrians", "loitering", "rendezvous", "convoy"]


def ensure_sample_site(path: Path, *, rebuild: bool = False, warmers: Any = None) -> Path:
    """Build the sample site at ``path`` unless a site is already there.

    The light ray-casting kernels the build renders with compile in a child process while
    it scans and grids (``warmers``: already started ones, else started here); a site
    already there stops them.
    """
    from demtrack.samplesite.build import build_sample_site
    from demtrack.samplesite.kernel_warmup import KernelWarmers

    if rebuild and (path / MANIFEST).exists():
        shutil.rmtree(path)
    if (path / MANIFEST).exists():
        if warmers is not None:
            warmers.stop()
        return path
    print(f"building the sample site in {path} ...", flush=True)
    build_sample_site(path, log=_say, warmers=warmers or KernelWarmers.start())
    return path


def _say(line: str) -> None:
    print(line, flush=True)


def _sample_site(args: argparse.Namespace) -> int:
    ensure_sample_site(args.dir, rebuild=args.force)
    print(f"sample site ready: {args.dir}")
    return 0


def _showcase_pixel(site: Site, sensor: Sensor, geo: Geolocator) -> tuple[float, float, str]:
    """A pixel whose ray meets the terrain several times and ends on a road, if any.

    That is the paper's case: a tree crown in front of the road takes the first hit.
    """
    import numpy as np

    intr = sensor.camera.intrinsics
    v, u = np.mgrid[8 : intr.height : 16, 8 : intr.width : 16]
    results = geo.geolocate(sensor.camera, u.ravel().astype(float), v.ravel().astype(float))
    if site.roads is not None:
        for g in results:
            if len(g.hits) < 2:
                continue
            first, last = g.hits[0].p_enu, g.hits[-1].p_enu
            var = site.dem.sample_variance(
                np.array([first[0], last[0]]), np.array([first[1], last[1]])
            )
            # Laser returns spread through a crown (high variance); a road is smooth.
            on_road = site.roads.distance_m(last[:1], last[1:2])[0] < 3.0
            if on_road and var[0] > 1.0 and var[1] < 0.05:
                return g.u, g.v, "(a crown in front of the road)"
    return (intr.width - 1) / 2, intr.height * 0.8, "(open ground)"


def _fresh_db(path: Path) -> None:
    """Remove a demo database (and its WAL files); the token file next to it stays."""
    for suffix in ("", "-wal", "-shm", "-journal"):
        p = path.with_name(path.name + suffix)
        if p.is_file():
            p.unlink()


def _live(args: argparse.Namespace) -> int:
    t_start = time.monotonic()
    live = live_overrides(args, DEMO_SCENARIOS)  # checks the options before any work
    # The children start before this process imports numba (about a second).
    from demtrack.samplesite.kernel_warmup import KernelWarmers

    if (args.site / MANIFEST).exists():
        # The build left the light kernels in numba's cache; the fast ones may be missing
        # (a first run stopped early): the same low-priority child loads or compiles them.
        # The tracker's kernels load in about a second (the replay waits for them).
        server_warmer = KernelWarmers.start(["tracker", "server"])
        try:
            _use_light_kernels()
            return _serve_demo(args, args.site, live, t_start, server_warmer)
        finally:
            server_warmer.stop()

    # Cold start: the light kernels the build and the first page need compile in a child
    # beside the scan and the server imports; a second child, at the lowest CPU priority,
    # compiles the fast kernels, and the server's warm-up waits for it before it loads
    # them and casts switch over (core.raycast.light.use_light_kernels); two more, at a low
    # priority too, compile the live tracker's kernels, and the replay waits for them.
    warmers = KernelWarmers.start()
    server_warmer = KernelWarmers.start(["fusion", "kalman", "server"])
    try:
        _use_light_kernels()
        site_dir = ensure_sample_site(args.site, warmers=_ImportServerWhileWaiting(warmers))
        return _serve_demo(args, site_dir, live, t_start, server_warmer)
    finally:
        warmers.stop()
        server_warmer.stop()


def _use_light_kernels() -> None:
    from demtrack.core.raycast.light import use_light_kernels

    use_light_kernels(True)


class _ImportServerWhileWaiting:
    """The build's warmers; when the build waits for them, the server is imported first.

    The build scans and grids while the kernels compile; the server's imports (seconds of
    CPU) then fill the time the build would spend waiting for them.
    """

    def __init__(self, warmers: Any) -> None:
        self.warmers = warmers

    def wait(self) -> list[int]:
        import demtrack.server.app  # noqa: F401

        return list(self.warmers.wait())

    def stop(self) -> None:
        self.warmers.stop()


def _serve_demo(
    args: argparse.Namespace,
    site_dir: Path,
    live: dict[str, Any],
    t_start: float,
    server_warmer: Any,
) -> int:
    from demtrack.samplesite.kernel_warmup import TRACKER_JOBS
    from demtrack.server.app import check_startup, create_app
    from demtrack.server.scene3d import display_host

    db = args.db if args.db is not None else site_dir / "demo.sqlite3"
    if not args.keep_db:
        _fresh_db(db)
    overrides: dict[str, Any] = {
        "site": site_dir,
        "db_path": db,
        "database_url": None,  # the demo's store is its fresh file, whatever the environment
        "scene3d": not args.no_3d,
        **live,
    }
    app = create_app(scenarios=scenario_source(live), **overrides)  # --video: renders videos
    check_startup(app)  # a broken site or database: one line and exit 2, not a traceback
    if server_warmer is not None:
        app.state.warm_after = server_warmer.wait
        # The replay starts once the tracker's kernels are in numba's cache: on a cold
        # start the low-priority children are still compiling them when the first
        # page is served (the replay thread compiling them too would hold the GIL).
        app.state.replay_after = functools.partial(server_warmer.wait, TRACKER_JOBS)
    settings = app.state.settings
    print(f"site {settings.site}, database {settings.resolved_db_path} (fresh each run)")
    print("starting the console (site, tracker, ray-casting kernels, 3D scene) ...", flush=True)

    def ready(port: int) -> None:
        base = f"http://{display_host(args.host)}:{port}"
        console = f"{base}/?token={app.state.token}"
        print(f"\ndemtrack console ready in {time.monotonic() - t_start:.1f} s")
        print(f"  console   {console}")
        print(f"  API docs  {base}/docs   (operator token {app.state.token})")
        print(f"  3D view   {app.state.viser_url or 'off (--no-3d)'}")
        print(
            f"  replaying {', '.join(settings.replay)} at {settings.replay_speed:g}x,"
            " looping; Ctrl-C stops",
            flush=True,
        )
        if args.open:
            import webbrowser

            webbrowser.open(console)

    return serve_app(app, args.host, args.port, args.log_level, on_ready=ready)


def _walkthrough(args: argparse.Namespace) -> int:
    from demtrack.core.site.folder import load_site

    site = load_site(ensure_sample_site(args.site))
    print(
        f"\nsite {site.name!r}: frame anchored at {site.frame.lat_deg:.6f}, "
        f"{site.frame.lon_deg:.6f}, h {site.frame.h_m:.1f} m (WGS84)"
    )
    lo, hi = site.dem.elevation_range()
    g = site.dem.grid
    print(
        f"DEM {g.ncols}x{g.nrows} cells of {g.cell_m} m, elevation {lo:.1f}..{hi:.1f} m; "
        f"{len(site.sensors)} sensors: {', '.join(site.sensors)}"
    )
    geo = site.geolocator()
    for sensor in site.sensors.values():
        u, v, why = _showcase_pixel(site, sensor, geo)
        print(
            f"\n{sensor.id} ({sensor.name}), pixel ({u:g}, {v:g}) {why}; every hit along the ray:"
        )
        print_geolocation(geo.geolocate(sensor.camera, [u], [v], rule="all")[0])
    print("\nnext: demtrack geolocate --sensor cam1 --pixel U V --rule all")
    return 0


def _demo(args: argparse.Namespace) -> int:
    return _walkthrough(args) if args.walkthrough else _live(args)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sample-site`` and ``demo`` commands."""
    p = sub.add_parser("sample-site", help="generate the synthetic Bushy Run sample site")
    p.add_argument("dir", type=Path, nargs="?", default=DEFAULT_SITE, help="output folder")
    p.add_argument("--force", action="store_true", help="rebuild even if the site exists")
    p.set_defaults(func=_sample_site)
    p = sub.add_parser(
        "demo",
        help="the live console on the sample site (built if needed), scenarios replaying",
        description="Build the sample site if it is missing, start the console server with"
        " scenarios replaying live and the 3D scene, and print their URLs.",
    )
    p.add_argument("--site", type=Path, default=DEFAULT_SITE, metavar="DIR")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=port, default=8000, help="port (default 8000; 0 = any free)")
    add_live_arguments(p, replay_default=DEMO_SCENARIOS)
    p.add_argument("--no-3d", action="store_true", help="do not serve the viser 3D scene")
    p.add_argument(
        "--db",
        type=Path,
        default=None,
        metavar="PATH",
        help="SQLite file (default: DIR/demo.sqlite3, emptied at each start)",
    )
    p.add_argument(
        "--keep-db", action="store_true", help="continue the database instead of emptying it"
    )
    p.add_argument("--open", action="store_true", help="open the console in a web browser")
    p.add_argument(
        "--walkthrough",
        action="store_true",
        help="print a text walk-through of one geolocation per camera instead",
    )
    p.add_argument(
        "--log-level", default="warning", choices=["critical", "error", "warning", "info", "debug"]
    )
    p.set_defaults(func=_demo)
