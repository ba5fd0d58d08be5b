"""Laser point clouds from files: LAS/LAZ (laspy), ``.npy`` and ``.csv``.

A :class:`PointCloud` keeps the coordinates as stored, the CRS when the file states one
(LAS/LAZ headers do; ``.npy``/``.csv`` cannot), and per-point classification and return
numbers when known, so a DEM can be built from ground returns (ASPRS class 2, a terrain
model) or from first returns (a surface model with trees and roofs, what Collins et al.
used).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputFileError

__all__ = ["GROUND_CLASS", "PointCloud", "read_point_cloud"]

#: ASPRS LAS classification code of ground points.
GROUND_CLASS = 2


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points as read from a file.

    Attributes
    ----------
    xyz : ndarray, float64, shape (n, 3)
        Coordinates in the file's CRS and units.
    crs_wkt : str or None
        The CRS the file states, if any.
    classification : ndarray, uint8, shape (n,), or None
        ASPRS classes (LAS/LAZ only).
    return_number : ndarray, shape (n,), or None
        1 for first returns (LAS/LAZ only).
    """

    xyz: np.ndarray
    crs_wkt: str | None = None
    classification: np.ndarray | None = None
    return_number: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.xyz)

    def select(self, *, ground_only: bool = False, first_returns: bool = False) -> PointCloud:
        """Keep ground-classified points and/or first returns.

        Raises
        ------
        InputFileError
            If the file holds no classification / return numbers to select on.
        """
        keep = np.ones(len(self.xyz), bool)
        if ground_only:
            if self.classification is None:
                raise InputFileError("ground-only needs classified points (LAS/LAZ)")
            keep &= self.classification == GROUND_CLASS
        if first_returns:
            if self.return_number is None:
                raise InputFileError("first-returns needs return numbers (LAS/LAZ)")
            keep &= self.return_number == 1
        return PointCloud(
            self.xyz[keep],
            self.crs_wkt,
            None if self.classification is None else self.classification[keep],
            None if self.return_number is None else self.return_number[keep],
        )


def _read_las(path: Path) -> PointCloud:
    import laspy
    from laspy.errors import LaspyException

    try:
        las = laspy.read(path)
    except (LaspyException, OSError, ValueError, EOFError, RuntimeError) as exc:
        # lazrs reports a truncated LAZ stream as a RuntimeError subclass (LazrsError).
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputFileError(
            f"cannot read LAS/LAZ file {path} (truncated or corrupt?): {msg}"
        ) from None
    if len(las.points) != las.header.point_count:
        raise InputFileError(
            f"LAS/LAZ file {path} is truncated: {len(las.points):,} of "
            f"{las.header.point_count:,} points"
        )
    try:
        crs = las.header.parse_crs()
    except Exception:  # noqa: BLE001 - a malformed CRS VLR is reported as "no CRS"
        crs = None
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    return PointCloud(
        xyz.astype(np.float64),
        crs.to_wkt() if crs is not None else None,
        np.asarray(las.classification, dtype=np.uint8),
        np.asarray(las.return_number),
    )


def _read_table(path: Path) -> np.ndarray:
    with path.open(encoding="utf-8") as fh:
        first = fh.readline()
    header = any(c.isalpha() for c in first.replace("e", "").replace("E", ""))
    return np.loadtxt(
        path,
        delimiter="," if "," in first else None,
        skiprows=1 if header else 0,
        usecols=(0, 1, 2),
        ndmin=2,
    )


def read_point_cloud(path: str | Path) -> PointCloud:
    """Read ``.las``/``.laz``, ``.npy`` (an (n, 3) array) or ``.csv``/``.txt``/``.xyz``.

    Raises
    ------
    InputFileError
        If the file is missing, of an unknown kind, malformed, or holds no points.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"point file not found: {path}")
    suffix = path.suffix.lower()
    if suffix in (".las", ".laz"):
        cloud = _read_las(path)
    else:
        try:
            if suffix == ".npy":
                pts = np.load(path, allow_pickle=False)
            elif suffix in (".csv", ".txt", ".xyz"):
                pts = _read_table(path)
            else:
                raise InputFileError(
                    f"unsupported point file {path.name}: use .las, .laz, .npy or .csv"
                )
        except ValueError as exc:
            msg = str(exc).splitlines()[0]
            raise InputFileError(f"malformed point file {path}: {msg}") from None
        pts = np.asarray(pts, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] < 3:
            raise InputFileError(f"{path}: points must be an (n, 3) array of x, y, z")
        cloud = PointCloud(np.ascontiguousarray(pts[:, :3]))
    if len(cloud) == 0:
        raise InputFileError(f"{path}: no points")
    return cloud
