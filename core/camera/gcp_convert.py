"""GCP files from other tools, and ImGRAFT's camera angles, in demtrack's conventions.

**ImGRAFT** (Messerli & Grinsted 2015, MATLAB; its ``camera.m`` and demos):

* GCP files are whitespace-separated text, one point a line, ``x y z u v`` (world
  coordinates in the DEM's projected CRS, then the pixel), ``%`` comment lines.
* Pixels are **1-based** (MATLAB): the centre of the top-left pixel is ``(1, 1)`` and
  ``inframe`` is ``1 <= u <= ncols``; its default principal point is
  ``(ncols + 1) / 2, (nrows + 1) / 2``. demtrack's pixel ``(0, 0)`` is that centre, so
  ``u_demtrack = u_imgraft - 1`` (and the same for ``v``, ``cx``, ``cy``).
* ``viewdir = [yaw pitch roll]`` in **radians**, the order of its ``fullmodel``. Its
  rotation ``R`` takes world offsets to camera axes (``p_cam = R (X - xyz)``; x right, y
  down, z forward as OpenCV); the optical axis is
  ``[cos(pitch) cos(yaw), cos(pitch) sin(yaw), -sin(pitch)]``: **yaw counter-clockwise
  from east** (0 = looking east, pi/2 = north) and **pitch positive downwards**. So
  ``az_deg = 90 - yaw_deg``, ``tilt_deg = -pitch_deg`` and ``roll_deg = roll`` in degrees
  (the same sense: positive lowers the image's right side); :func:`angles_from_imgraft`
  goes through the rotation matrix, so it also holds at any pitch.
* World axes are the projected CRS's grid axes (x east, y north of the *grid*); the site
  frame is true-north ENU, so a grid yaw also needs the meridian convergence (see
  ``core.camera.pose``) when the angles are carried over, not the GCP coordinates (those
  are converted exactly through the CRS).

**CSV** ``u,v,x,y,z`` (optionally ``name``) with a declared CRS: the file format of
:mod:`~demtrack.core.camera.gcp_io`, whose pixels are already 0-based.

:func:`convert_gcps` reads either, optionally re-projects ``x, y, z`` to another CRS
(pyproj, ``always_xy=True``; heights pass through unchanged unless both CRSs are 3-D), and
:func:`write_gcp_csv` writes demtrack's GCP CSV atomically (temporary file and
:func:`os.replace`).
"""

from __future__ import annotations

import math
import os
import re
import uuid
from pathlib import Path

import numpy as np

from ..errors import CalibrationError, DemtrackError, InputFileError
from ..geo.geodesy import as_crs
from .gcp_io import LOCAL_CRS, GcpFile, read_gcp_csv, read_gcp_text
from .pinhole import Camera, Intrinsics, rotation_from_azimuth_tilt_roll

__all__ = [
    "GCP_FORMATS",
    "angles_from_imgraft",
    "convert_gcps",
    "gcp_csv_text",
    "imgraft_rotation",
    "imgraft_viewdir",
    "read_gcps",
    "read_imgraft_gcps",
    "reproject_gcps",
    "write_gcp_csv",
]

#: GCP file formats read by :func:`read_gcps`.
GCP_FORMATS = ("csv", "imgraft")
_SPLIT = re.compile(r"[\s,;]+")
_UNIT_INTRINSICS = Intrinsics(1.0, 1.0, 0.0, 0.0, 1, 1)


def read_imgraft_gcps(path: str | Path) -> GcpFile:
    """Read an ImGRAFT GCP file (``x y z u v``, 1-based pixels) as 0-based GCPs.

    Returns
    -------
    GcpFile
        ``uv`` = ImGRAFT's pixel minus 1; ``xyz`` as given; no CRS (the file has none);
        each point named after its line, ``line7``.

    Raises
    ------
    InputFileError
        On a missing or non-text file, a line without exactly five numbers, or no points.
    """
    path = Path(path)
    text = read_gcp_text(path)
    rows: list[list[float]] = []
    lines_no: list[int] = []
    for k, line in enumerate(text.splitlines(), start=1):
        s = line.split("%", 1)[0].strip()
        if not s or s.startswith("#"):
            continue
        tokens = [t for t in _SPLIT.split(s) if t]
        try:
            vals = [float(t) for t in tokens]
        except ValueError:
            vals = []
        if len(vals) != 5 or not all(math.isfinite(v) for v in vals):
            raise InputFileError(
                f"ImGRAFT GCP file {path}: line {k} must hold five numbers x y z u v, got {s!r}"
            )
        rows.append(vals)
        lines_no.append(k)
    if not rows:
        raise InputFileError(f"ImGRAFT GCP file {path} has no control points")
    arr = np.asarray(rows, dtype=np.float64)
    names = tuple(f"line{k}" for k in lines_no)
    return GcpFile(names, arr[:, 3:5] - 1.0, arr[:, 0:3], None, None)


def read_gcps(path: str | Path, fmt: str = "csv") -> GcpFile:
    """Read a GCP file in one of :data:`GCP_FORMATS` (pixels 0-based on return)."""
    if fmt == "csv":
        return read_gcp_csv(path)
    if fmt == "imgraft":
        return read_imgraft_gcps(path)
    raise CalibrationError(f"unknown GCP format {fmt!r}; choose from {','.join(GCP_FORMATS)}")


def reproject_gcps(gcps: GcpFile, src_crs: str, dst_crs: str) -> GcpFile:
    """``x, y, z`` from ``src_crs`` to ``dst_crs`` (pyproj, ``always_xy=True``).

    Raises
    ------
    CalibrationError
        On an unknown CRS, ``local`` on either side, or a failed transformation.
    """
    if LOCAL_CRS in (src_crs.strip().lower(), dst_crs.strip().lower()):
        raise CalibrationError("'local' (the site frame) cannot be re-projected without a site")
    from pyproj import Transformer
    from pyproj.exceptions import ProjError

    try:
        t = Transformer.from_crs(as_crs(src_crs), as_crs(dst_crs), always_xy=True)
        x, y, z = t.transform(gcps.xyz[:, 0], gcps.xyz[:, 1], gcps.xyz[:, 2], errcheck=True)
    except DemtrackError as exc:
        raise CalibrationError(f"GCP CRS: {exc}") from None
    except ProjError as exc:
        msg = str(exc).splitlines()[0] if str(exc) else "failed"
        raise CalibrationError(f"GCPs from {src_crs} to {dst_crs}: {msg}") from None
    xyz = np.column_stack([x, y, z]).astype(np.float64)
    if not np.isfinite(xyz).all():
        raise CalibrationError(f"GCPs from {src_crs} to {dst_crs}: some points do not convert")
    return GcpFile(gcps.names, gcps.uv.copy(), xyz, dst_crs, gcps.vertical)


def convert_gcps(
    path: str | Path,
    fmt: str,
    *,
    crs: str | None = None,
    to_crs: str | None = None,
    vertical: str | None = None,
) -> GcpFile:
    """Read ``path`` (``fmt``), state its CRS and vertical datum, optionally re-project.

    Raises
    ------
    CalibrationError
        When no CRS is known (ImGRAFT files carry none: pass ``crs``).
    """
    gf = read_gcps(path, fmt)
    src = crs or gf.crs
    if src is None:
        raise CalibrationError(
            f"{path}: the GCPs' CRS is not stated; pass --crs (ImGRAFT files carry none)"
        )
    vert = vertical or gf.vertical
    gf = GcpFile(gf.names, gf.uv, gf.xyz, src, vert)
    if to_crs is not None and to_crs != src:
        gf = reproject_gcps(gf, src, to_crs)
    return gf


def gcp_csv_text(gcps: GcpFile) -> str:
    """Text of demtrack's GCP CSV (``# crs:``/``# vertical:`` header lines, 0-based pixels)."""
    lines = []
    if gcps.crs:
        lines.append(f"# crs: {gcps.crs}")
    if gcps.vertical:
        lines.append(f"# vertical: {gcps.vertical}")
    lines.append("name,u,v,x,y,z")
    for name, (u, v), (x, y, z) in zip(gcps.names, gcps.uv, gcps.xyz, strict=True):
        safe = name.replace(",", " ").strip()
        if safe.startswith("#"):  # would read as a comment line
            safe = "gcp" + safe.lstrip("#")
        lines.append(f"{safe},{u:.6f},{v:.6f},{x:.6f},{y:.6f},{z:.6f}")
    return "\n".join(lines) + "\n"


def write_gcp_csv(path: str | Path, gcps: GcpFile) -> None:
    """Write :func:`gcp_csv_text` to ``path`` atomically (temporary file + os.replace)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.part")
    try:
        tmp.write_text(gcp_csv_text(gcps), encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def imgraft_rotation(yaw_rad: float, pitch_rad: float, roll_rad: float) -> np.ndarray:
    """ImGRAFT's ``camera.R`` for ``viewdir = [yaw pitch roll]``: world -> camera, (3, 3)."""
    c1, c2, c3 = math.cos(yaw_rad), math.cos(pitch_rad), math.cos(roll_rad)
    s1, s2, s3 = math.sin(yaw_rad), math.sin(pitch_rad), math.sin(roll_rad)
    r = np.array(
        [
            [s3 * s2 * c1 - c3 * s1, s3 * s2 * s1 + c3 * c1, s3 * c2],
            [c3 * s2 * c1 + s3 * s1, c3 * s2 * s1 - s3 * c1, c3 * c2],
            [c2 * c1, c2 * s1, -s2],
        ]
    )
    r[0:2, :] *= -1.0
    return r


def angles_from_imgraft(
    yaw_rad: float, pitch_rad: float, roll_rad: float
) -> tuple[float, float, float]:
    """The demtrack ``(az_deg, tilt_deg, roll_deg)`` for an ImGRAFT ``viewdir`` (grid axes)."""
    r_world_cam = imgraft_rotation(yaw_rad, pitch_rad, roll_rad).T
    return Camera(_UNIT_INTRINSICS, np.zeros(3), r_world_cam).azimuth_tilt_roll_deg()


def imgraft_viewdir(az_deg: float, tilt_deg: float, roll_deg: float) -> tuple[float, float, float]:
    """ImGRAFT's ``viewdir`` (radians, yaw in (-pi, pi]) for demtrack's angles."""
    r = rotation_from_azimuth_tilt_roll(az_deg, tilt_deg, roll_deg).T  # world -> camera
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 2])))
    yaw = math.atan2(r[2, 1], r[2, 0])
    roll = math.atan2(-r[0, 2], -r[1, 2])
    return yaw, pitch, roll
