"""A store's detections (and the poses stamped at their moments) as archive rows.

Reads only the store's public read methods (``detections``, ``sensor_counts``,
``poses``), so either store serves: a SQLite file (or a ``sqlite:///PATH`` URL) or a
PostgreSQL database (``postgresql://`` URL), opened by the server's own
:func:`demtrack.server.store.opening.open_store`.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pyarrow as pa

from demtrack.core.errors import InputFileError

from .archive import table_from_detections, write_archive

__all__ = ["export_store", "open_store_source", "store_table"]

_PAGE = 50_000


@contextmanager
def open_store_source(source: str) -> Iterator[Any]:
    """The store a path or URL names (:func:`demtrack.server.store.opening.open_store`).

    Closed on exit. ``sqlite:///PATH`` names a file; ``postgresql://`` a database.

    Raises
    ------
    InputFileError
        A missing SQLite file.
    SettingsError
        A database that cannot be used (one line, the URL without its password).
    """
    from demtrack.server.store.opening import open_store

    if source.startswith("sqlite:///"):
        source = source[len("sqlite:///") :]  # sqlite:////abs/path keeps its leading /
    if "://" not in source and not Path(source).is_file():
        raise InputFileError(f"store {source} does not exist")
    store = open_store(source)
    try:
        yield store
    finally:
        store.close()


def _pose_map(store: Any, sensors: list[str]) -> dict[tuple[str, float], tuple[float, float, Any]]:
    """``(sensor, t_s) -> (pan, tilt, hfov)`` of every stored pose sample."""
    out = {}
    for sid in sensors:
        for body in store.poses(sid, limit=2**62):
            if "pan_deg" in body and "tilt_deg" in body:
                key = (sid, float(body["t_s"]))
                out[key] = (float(body["pan_deg"]), float(body["tilt_deg"]), body.get("hfov_deg"))
    return out


def store_table(source: str) -> pa.Table:
    """Every stored detection as an archive row, ``seq`` = its store id.

    A detection gets the pose fields of the sensor's pose sample stamped at exactly its
    time, where there is one (an inline pose as ingested); other telemetry is not an
    archive row's.
    """
    with open_store_source(source) as store:
        rows: list[tuple[int, Any]] = []
        after = 0
        while True:
            page = store.detections(after_id=after, limit=_PAGE)
            if not page:
                break
            rows += page
            after = page[-1][0]
        poses = _pose_map(store, sorted(store.sensor_counts()))
    dets = [d for _, d in rows]
    inline = {}
    for i, d in enumerate(dets):
        p = poses.get((d.sensor, d.t_s))
        if p is not None:
            inline[i] = p
    return table_from_detections(dets, inline, seq=[i for i, _ in rows])


def export_store(source: str, out_dir: str | os.PathLike[str]) -> int:
    """Write a store's detections as an archive folder; returns the row count."""
    return write_archive(store_table(source), out_dir)
