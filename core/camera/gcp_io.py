"""Ground control points from a CSV file: pixel <-> world coordinates in any CRS.

Format (UTF-8 text)::

    # crs: EPSG:32617            CRS of x, y, z ("local" = the site frame e, n, u in m)
    # vertical: orthometric      heights: "ellipsoidal" (WGS84) or "orthometric" (h = H + N)
    name,u,v,x,y,z
    church spire,812.4,233.0,589312.10,4467321.55,352.10
    ...

* ``u, v``: pixel (column, row), ``(0, 0)`` the centre of the top-left pixel.
* ``x, y``: easting/northing in the CRS's unit (projected) or longitude/latitude in
  degrees (geographic), whatever the CRS's axis order; ``z`` the height in the CRS's
  vertical (or horizontal, for a projected 2-D CRS) unit: a ftUS state plane means ftUS.
* ``name`` is optional (rows are then named ``#1``, ``#2``, ...). Columns may come in any
  order; lines starting with ``#`` other than the two keys above are comments.

The command line's ``--gcp-crs`` / ``--gcp-vertical`` override the header lines. A
height is never guessed: without a vertical datum the file is refused, except for
``local`` and EPSG:4979 (3-D WGS84, ellipsoidal by definition).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CalibrationError, DemtrackError, InputFileError
from ..geo.geodesy import LocalFrame, as_crs

__all__ = ["LOCAL_CRS", "Gcp", "GcpFile", "gcps_to_local", "read_gcp_csv", "read_gcp_text"]

#: The ``crs`` value meaning "already in the site frame (e, n, u in metres)".
LOCAL_CRS = "local"
_REQUIRED = ("u", "v", "x", "y", "z")


@dataclass(frozen=True, eq=False)
class Gcp:
    """One control point: its pixel and its position in the site frame.

    Attributes
    ----------
    name : str
    u, v : float
        Pixel (column, row).
    p_enu : ndarray, shape (3,)
        Site-frame position (m).
    """

    name: str
    u: float
    v: float
    p_enu: np.ndarray


@dataclass(frozen=True, eq=False)
class GcpFile:
    """A parsed GCP file, coordinates as given.

    Attributes
    ----------
    names : tuple of str
    uv : ndarray, shape (k, 2)
    xyz : ndarray, shape (k, 3)
        In ``crs``.
    crs : str or None
        From the header (None if absent).
    vertical : str or None
        ``"ellipsoidal"``, ``"orthometric"`` or None.
    """

    names: tuple[str, ...]
    uv: np.ndarray
    xyz: np.ndarray
    crs: str | None
    vertical: str | None


def read_gcp_text(path: Path) -> str:
    """The text of a GCP file; :class:`InputFileError` when missing or not UTF-8."""
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputFileError(f"GCP file not found: {path}") from None
    except UnicodeDecodeError:
        raise InputFileError(f"GCP file {path} is not UTF-8 text") from None


def read_gcp_csv(path: str | Path) -> GcpFile:
    """Parse a GCP CSV file (see the module notes).

    Raises
    ------
    InputFileError
        On a missing file, missing columns, non-numeric or non-finite values, or no rows.
    """
    path = Path(path)
    text = read_gcp_text(path)
    crs = vertical = None
    body = []
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("#"):
            key, _, value = s[1:].partition(":")
            key = key.strip().lower()
            if key == "crs" and value.strip():
                crs = value.strip()
            elif key == "vertical" and value.strip():
                vertical = value.strip().lower()
            continue
        if s:
            body.append(line)
    rows = list(csv.reader(io.StringIO("\n".join(body))))
    if not rows:
        raise InputFileError(f"GCP file {path} has no header row")
    header = [h.strip().lower() for h in rows[0]]
    missing = [c for c in _REQUIRED if c not in header]
    if missing:
        raise InputFileError(
            f"GCP file {path}: header must name columns u,v,x,y,z (name optional); "
            f"missing {','.join(missing)}"
        )
    idx = {c: header.index(c) for c in _REQUIRED}
    i_name = header.index("name") if "name" in header else None
    names: list[str] = []
    values: list[list[float]] = []
    for k, row in enumerate(rows[1:], start=2):
        try:
            vals = [float(row[idx[c]]) for c in _REQUIRED]
        except (ValueError, IndexError):
            raise InputFileError(f"GCP file {path}: data row {k - 1} is malformed: {row}") from None
        if not all(math.isfinite(v) for v in vals):
            raise InputFileError(f"GCP file {path}: data row {k - 1} has a non-finite value")
        values.append(vals)
        name = row[i_name].strip() if i_name is not None and i_name < len(row) else ""
        names.append(name or f"#{len(names) + 1}")
    if not values:
        raise InputFileError(f"GCP file {path} has no control points")
    if len(set(names)) != len(names):
        raise InputFileError(f"GCP file {path}: GCP names must be unique")
    arr = np.asarray(values, dtype=np.float64)
    return GcpFile(tuple(names), arr[:, :2], arr[:, 2:], crs, vertical)


def gcps_to_local(
    gcps: GcpFile,
    frame: LocalFrame,
    *,
    crs: str | None = None,
    vertical: str | None = None,
    geoid_undulation_m: float = 0.0,
) -> tuple[Gcp, ...]:
    """Control points in the site frame.

    Parameters
    ----------
    gcps : GcpFile
    frame : LocalFrame
    crs, vertical : str, optional
        Override the file's header.
    geoid_undulation_m : float
        The site's ``N``, used for orthometric heights.

    Raises
    ------
    CalibrationError
        When the CRS or the vertical datum is missing or unknown.
    """
    crs = crs or gcps.crs
    vertical = (vertical or gcps.vertical or "").lower() or None
    if crs is None:
        raise CalibrationError(
            "the GCPs' CRS is not stated: add a '# crs: EPSG:XXXX' line to the file or "
            "pass --gcp-crs"
        )
    if crs.strip().lower() == LOCAL_CRS:
        p = gcps.xyz.copy()
    else:
        try:
            c = as_crs(crs)
        except DemtrackError as exc:
            raise CalibrationError(f"GCP CRS: {exc}") from None
        if vertical is None and c.to_epsg() == 4979:
            vertical = "ellipsoidal"
        if vertical not in ("ellipsoidal", "orthometric"):
            raise CalibrationError(
                "the GCPs' vertical datum is not stated: add '# vertical: ellipsoidal' or "
                "'# vertical: orthometric' to the file, or pass --gcp-vertical"
            )
        n_geoid = geoid_undulation_m if vertical == "orthometric" else 0.0
        try:
            e, n, u = frame.to_enu_from_crs(
                gcps.xyz[:, 0], gcps.xyz[:, 1], gcps.xyz[:, 2], c, geoid_undulation_m=n_geoid
            )
        except DemtrackError as exc:
            raise CalibrationError(f"GCP coordinates: {exc}") from None
        p = np.column_stack([np.atleast_1d(e), np.atleast_1d(n), np.atleast_1d(u)])
    return tuple(
        Gcp(name, float(uv[0]), float(uv[1]), p[k].copy())
        for k, (name, uv) in enumerate(zip(gcps.names, gcps.uv, strict=True))
    )
