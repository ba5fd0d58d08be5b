"""``demtrack archive export|convert|synth``: detection archives (Parquet by sensor and hour).

``export`` writes a store's detections (a SQLite file, or a database URL); ``convert`` a
detection file (``.jsonl``, ``.csv``) or another archive; ``synth`` the synthetic
reprocessing archive: a site of ``--cameras`` cameras derived from the sample site and
at least ``--detections`` rendered detections (:mod:`demtrack.reprocess.synth`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from demtrack.core.errors import InputFileError

from .common import positive_int

__all__ = ["register"]


def _export(args: argparse.Namespace) -> int:
    from demtrack.reprocess.store_export import export_store

    source = args.database_url or args.db
    if source is None:
        raise InputFileError("archive export: give --db FILE.sqlite3 or --database-url URL")
    n = export_store(str(source), Path(args.output))
    print(f"{n} detection(s) -> {args.output}")
    return 0


def _convert(args: argparse.Namespace) -> int:
    from demtrack.core.geolocation.fix_builder import sensor_sizes
    from demtrack.core.site.folder import load_site
    from demtrack.reprocess.archive import write_archive
    from demtrack.reprocess.sources import read_archive

    read = read_archive(args.source, sensor_sizes(load_site(args.site)))
    print(read.summary())
    write_archive(read.table, Path(args.output))
    print(f"{read.table.num_rows} detection(s) -> {args.output}")
    return 0


def _synth(args: argparse.Namespace) -> int:
    from demtrack.reprocess.synth import make_camera_site, synth_archive

    out = Path(args.output)
    site_out = Path(args.site_out) if args.site_out else out.with_name(out.name + "-site")
    t0 = time.perf_counter()
    if not (site_out / "site.json").is_file():
        make_camera_site(args.site, site_out, args.cameras)
        print(f"site with {args.cameras} cameras -> {site_out}")
    got = synth_archive(site_out, out, args.detections, seeds=args.variants)
    hours = (got["t_last"] - got["t_first"]) / 3600.0
    print(
        f"{got['detections']} detection(s): {got['copies']} copies of {got['variants']}"
        f" rendered scenario variant(s) over {hours:.1f} h -> {out}"
        f" ({time.perf_counter() - t0:.0f} s); reprocess with --site {site_out}"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``archive`` command."""
    p = sub.add_parser("archive", help="detection archives: export, convert, synth")
    asub = p.add_subparsers(dest="archive", metavar="ACTION", required=True)
    e = asub.add_parser("export", help="a store's detections as a Parquet archive")
    e.add_argument("--db", metavar="FILE", help="the console's SQLite store")
    e.add_argument("--database-url", metavar="URL", help="a store's database URL")
    e.add_argument("-o", "--output", required=True, metavar="DIR", help="new archive folder")
    e.set_defaults(func=_export)
    c = asub.add_parser("convert", help="a detection file (.jsonl, .csv) as a Parquet archive")
    c.add_argument("source", metavar="SRC", help="detections (.jsonl, .csv, .parquet, folder)")
    c.add_argument("--site", default="sample_site/site", help="site folder (its sensors)")
    c.add_argument("-o", "--output", required=True, metavar="DIR", help="new archive folder")
    c.set_defaults(func=_convert)
    s = asub.add_parser("synth", help="the synthetic reprocessing archive (>= 1 M detections)")
    s.add_argument("--site", default="sample_site/site", help="the sample site to derive from")
    s.add_argument("--cameras", type=positive_int, default=12, help="cameras (default 12)")
    s.add_argument("--detections", type=positive_int, default=1_000_000, help="at least this many")
    s.add_argument(
        "--variants", type=positive_int, default=2, help="render seeds per scenario (default 2)"
    )
    s.add_argument(
        "--site-out", metavar="DIR", help="where the derived site goes (default OUT-site)"
    )
    s.add_argument("-o", "--output", required=True, metavar="DIR", help="new archive folder")
    s.set_defaults(func=_synth)
