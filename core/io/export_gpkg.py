"""GeoPackage track files, written by GDAL through pyogrio, with a spatial index.

Two layers in EPSG:4979 (WGS84 geographic 3D: x longitude, y latitude, z the height above
the ellipsoid, the CRS saying so itself):

- ``tracks``: ``MULTILINESTRING Z``, one feature per track, one line per run between gaps
  (a one-point run is a zero-length line, its point twice); ``track_id``, ``class``,
  ``sensors``, ``t_start_s``, ``t_end_s``, ``time_start_utc``, ``time_end_utc``
  (DateTime, UTC), ``n_points``, ``n_segments``, ``n_gaps``, ``gaps`` (JSON, s).
- ``track_points``: ``POINT Z``, one per point; ``track_id``, ``class``, ``segment`` (run
  index), ``t_s``, ``time_utc``, ``sensors``, ``fix_indices``, ``e_m``/``n_m``/``u_m``
  (site frame), ``h_wgs84_m`` (ellipsoidal) and ``elevation_m`` (orthometric, null without
  a geoid model).

GDAL writes the GeoPackage tables, the binary geometries and an R-tree spatial index per
layer (``SPATIAL_INDEX=YES``), which a hand-written writer would have to reimplement with
its triggers; each layer's ``gpkg_contents.description`` carries the height and time notes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyogrio.raw
import shapely

from .export_common import ExportTrack, HeightModel, TimeBase

__all__ = ["GPKG_APPLICATION_ID", "GPKG_CRS", "write_gpkg"]

#: ``PRAGMA application_id`` of a GeoPackage: the ASCII bytes "GPKG".
GPKG_APPLICATION_ID = 0x47504B47
GPKG_CRS = "EPSG:4979"


def _times(times: TimeBase, t_s: Sequence[float]) -> np.ndarray:
    # Naive datetime64 in UTC; the UTC offset (0) is given to GDAL separately.
    return np.array(
        [np.datetime64(times.datetime(t).replace(tzinfo=None), "ms") for t in t_s],
        dtype="datetime64[ms]",
    )


def _utc(n: int) -> np.ndarray:
    # GDAL's time zone flag (RFC 56): 100 is UTC.
    return np.full(n, 100, dtype=np.int32)


def _line(xt: ExportTrack) -> shapely.MultiLineString:
    xyz = np.column_stack([xt.lon_deg, xt.lat_deg, xt.h_m])
    parts = [xyz[list(run)] for run in xt.runs]
    return shapely.MultiLineString([p if len(p) > 1 else np.vstack([p, p]) for p in parts])


def write_gpkg(
    path: str | os.PathLike[str],
    tracks: Sequence[ExportTrack],
    heights: HeightModel,
    times: TimeBase,
    *,
    include_points: bool = True,
) -> None:
    """Write the GeoPackage of ``tracks`` (layers ``tracks`` and ``track_points``).

    Parameters
    ----------
    path : path
        Output file (replaced if it exists).
    tracks : sequence of ExportTrack
        Prepared tracks (:func:`~demtrack.core.io.export_common.prepare_tracks`).
    heights : HeightModel
        Fills ``elevation_m`` (null without a geoid model).
    times : TimeBase
        The UTC times of the ``time_*`` columns.
    include_points : bool
        Fill the ``track_points`` layer (it is created either way).
    """
    path = Path(path)
    path.unlink(missing_ok=True)
    note = f"z and h_wgs84_m: metres above the WGS84 ellipsoid; {heights.note}; {times.note}"
    # GeoPackage 1.3, which GDAL before 3.7 (and so older QGIS) reads without a warning.
    common = {
        "driver": "GPKG",
        "crs": GPKG_CRS,
        "promote_to_multi": False,
        "dataset_options": {"VERSION": "1.3"},
    }
    tids = np.array([xt.track.id for xt in tracks], dtype=np.int64)
    t0 = [xt.t_s[0] for xt in tracks]
    t1 = [xt.t_s[-1] for xt in tracks]
    line_fields = {
        "track_id": tids,
        "class": np.array([xt.track.cls for xt in tracks], dtype=object),
        "sensors": np.array([",".join(sorted(xt.track.sensors)) for xt in tracks], dtype=object),
        "t_start_s": np.array(t0, dtype=float),
        "t_end_s": np.array(t1, dtype=float),
        "time_start_utc": _times(times, t0),
        "time_end_utc": _times(times, t1),
        "n_points": np.array([len(xt.track.points) for xt in tracks], dtype=np.int32),
        "n_segments": np.array([len(xt.runs) for xt in tracks], dtype=np.int32),
        "n_gaps": np.array([len(xt.track.gaps) for xt in tracks], dtype=np.int32),
        "gaps": np.array(
            [json.dumps([[a, b] for a, b in xt.track.gaps]) for xt in tracks], dtype=object
        ),
    }
    geoms = np.array(
        [shapely.to_wkb(_line(xt), flavor="iso", output_dimension=3) for xt in tracks],
        dtype=object,
    )
    pyogrio.raw.write(
        path,
        geoms,
        list(line_fields.values()),
        list(line_fields),
        layer="tracks",
        geometry_type="MultiLineString Z",
        layer_options={"SPATIAL_INDEX": "YES", "DESCRIPTION": f"demtrack tracks; {note}"},
        gdal_tz_offsets={"time_start_utc": _utc(len(tracks)), "time_end_utc": _utc(len(tracks))},
        **common,
    )
    rows = [(xt, k, i) for xt in tracks for k, run in enumerate(xt.runs) for i in run]
    if not include_points:
        rows = []
    ortho = heights.orthometric
    pt_fields = {
        "track_id": np.array([xt.track.id for xt, _, _ in rows], dtype=np.int64),
        "class": np.array([xt.track.cls for xt, _, _ in rows], dtype=object),
        "segment": np.array([k for _, k, _ in rows], dtype=np.int32),
        "t_s": np.array([xt.track.points[i].t_s for xt, _, i in rows], dtype=float),
        "time_utc": _times(times, [xt.track.points[i].t_s for xt, _, i in rows]),
        "sensors": np.array([",".join(xt.track.points[i].sensors) for xt, _, i in rows], object),
        "fix_indices": np.array(
            [",".join(str(j) for j in xt.track.points[i].fix_indices) for xt, _, i in rows],
            dtype=object,
        ),
        **{
            name: np.array([float(xt.track.points[i].p_enu[c]) for xt, _, i in rows], float)
            for c, name in enumerate(("e_m", "n_m", "u_m"))
        },
        "h_wgs84_m": np.array([xt.h_m[i] for xt, _, i in rows], dtype=float),
        "elevation_m": np.array(
            [xt.abs_h_m[i] if ortho else np.nan for xt, _, i in rows], dtype=float
        ),
    }
    pt_wkb = [
        shapely.to_wkb(
            shapely.Point(xt.lon_deg[i], xt.lat_deg[i], xt.h_m[i]),
            flavor="iso",
            output_dimension=3,
        )
        for xt, _, i in rows
    ]
    pyogrio.raw.write(
        path,
        np.array(pt_wkb, dtype=object),
        list(pt_fields.values()),
        list(pt_fields),
        layer="track_points",
        geometry_type="Point Z",
        layer_options={"SPATIAL_INDEX": "YES", "DESCRIPTION": f"demtrack track points; {note}"},
        gdal_tz_offsets={"time_utc": _utc(len(rows))},
        **common,
    )
