"""Geoid models: the undulation ``N(lat, lon)`` between the WGS84 ellipsoid and a geoid.

Heights inside demtrack are ellipsoidal (``h``, metres above the WGS84 ellipsoid).
Sea-level (orthometric) heights ``H`` are above a geoid, and the two are related by the
geoid undulation ``N``, the geoid's height above the ellipsoid at that place::

    h = H + N(lat, lon)          H = h - N(lat, lon)

A :class:`GeoidModel` is one of three kinds:

- ``"ellipsoidal"``: no geoid; ``N = 0`` and the "orthometric" heights are the ellipsoidal
  ones (every output that uses it says so).
- ``"constant"``: one stated undulation ``N`` for the whole site (the old ``site.json``
  ``geoid_undulation_m``); right to a few centimetres over a few kilometres for EGM96.
- ``"grid"``: ``N`` evaluated at each point from a PROJ vertical-offset grid: EGM96 from
  ``egm96_15.gtx`` (15' global grid; Debian's ``proj-data`` installs it as
  ``/usr/share/proj/egm96_15.gtx``; pyproj's wheel ships no grid) or any grid PROJ reads
  (``.gtx``, or a GeoTIFF in geographic coordinates, e.g. a national geoid such as
  GEOID18 or OSGM15). PROJ's ``vgridshift`` interpolates bilinearly between the grid's
  node values (a value belongs to its node; no half-cell shift).

Nothing here downloads anything, reads the environment or falls back silently: a grid
that is missing, unreadable, or that does not cover a point raises
:class:`~demtrack.core.errors.GeoidError` naming the grid.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import GeoidError

__all__ = [
    "EGM96_GRID",
    "GeoidKind",
    "GeoidModel",
    "as_geoid",
    "default_grid_dirs",
    "find_grid",
]

#: The file name of PROJ's EGM96 15' grid (Debian: ``/usr/share/proj/egm96_15.gtx``).
EGM96_GRID = "egm96_15.gtx"
#: Folders searched for named grids after PROJ's own data folder (Debian's and /usr/local's).
_SYSTEM_GRID_DIRS = ("/usr/share/proj", "/usr/local/share/proj")

GeoidKind = Literal["ellipsoidal", "constant", "grid"]


def default_grid_dirs() -> tuple[Path, ...]:
    """Where named grids are looked for: pyproj's data folder(s), then Debian's.

    pyproj's data folder may list several paths (it honours ``PROJ_DATA``, which is
    pyproj's reading of the environment, not demtrack's).
    """
    import os

    import pyproj.datadir

    dirs: list[Path] = []
    for d in (pyproj.datadir.get_data_dir(), *_SYSTEM_GRID_DIRS):
        dirs += [Path(p) for p in str(d).split(os.pathsep) if p]
    return tuple(dict.fromkeys(dirs))


def find_grid(filename: str, dirs: Iterable[str | Path] | None = None) -> Path | None:
    """The first ``dir / filename`` that is a file, None when no folder has it.

    Parameters
    ----------
    filename : str
        A grid file name (``"egm96_15.gtx"``).
    dirs : iterable of path, optional
        Folders to search, in order; default :func:`default_grid_dirs`.
    """
    for d in default_grid_dirs() if dirs is None else dirs:
        path = Path(d) / filename
        if path.is_file():
            return path
    return None


def _pipeline(grid: Path) -> str:
    # vgridshift adds multiplier x grid value to z; z = 0 in, so the output z is N.
    return (
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad"
        f" +step +proj=vgridshift +grids={grid} +multiplier=1"
        " +step +proj=unitconvert +xy_in=rad +xy_out=deg"
    )


@dataclass(frozen=True)
class GeoidModel:
    """The geoid undulation ``N`` (m) of a site's vertical datum, per point.

    Build one with :meth:`ellipsoidal`, :meth:`constant`, :meth:`from_grid` or
    :meth:`egm96`, not with the constructor.

    Parameters
    ----------
    kind : {"ellipsoidal", "constant", "grid"}
        See the module docstring.
    name : str
        The geoid's name: ``"EGM96"``, a grid's stem (``"us_noaa_g2018u0"``) or a user's
        name for it, ``"constant N = -33.9 m"``, or ``"WGS84 ellipsoid"``.
    n_m : float
        The constant undulation (m); 0 for the other kinds.
    grid_path : Path or None
        The grid file (``kind="grid"`` only).
    """

    kind: GeoidKind
    name: str
    n_m: float = 0.0
    grid_path: Path | None = None
    _local: threading.local = field(
        default_factory=threading.local, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if self.kind not in ("ellipsoidal", "constant", "grid"):
            raise GeoidError(f"unknown geoid model kind {self.kind!r}")
        if not math.isfinite(self.n_m):
            raise GeoidError(f"geoid undulation must be finite, got {self.n_m!r}")
        if (self.kind == "grid") != (self.grid_path is not None):
            raise GeoidError("a geoid grid model needs its grid file (and only it)")

    # ------------------------------------------------------------------ builders
    @classmethod
    def ellipsoidal(cls) -> GeoidModel:
        """No geoid: ``N = 0``, heights stay above the WGS84 ellipsoid."""
        return cls("ellipsoidal", "WGS84 ellipsoid")

    @classmethod
    def constant(cls, n_m: float, name: str | None = None) -> GeoidModel:
        """One undulation ``n_m`` (m, ``h = H + N``) for every point."""
        try:
            n = float(n_m)
        except (TypeError, ValueError):
            raise GeoidError(f"geoid undulation must be a number, got {n_m!r}") from None
        if not math.isfinite(n):
            raise GeoidError(f"geoid undulation must be finite, got {n_m!r}")
        return cls("constant", name or f"constant N = {n:g} m", n)

    @classmethod
    def from_grid(cls, path: str | Path, name: str | None = None) -> GeoidModel:
        """``N`` from a PROJ-readable vertical-offset grid (``.gtx``, GeoTIFF), per point.

        The grid is opened at once, so a missing or unreadable file is reported here.

        Raises
        ------
        GeoidError
            If ``path`` is not a file or PROJ cannot read it as a grid.
        """
        grid = Path(path)
        if not grid.is_file():
            raise GeoidError(f"geoid grid {grid} does not exist")
        model = cls("grid", name or grid.stem, 0.0, grid.resolve())
        model._transformer()  # fail now, with the grid named, not at the first export
        return model

    @classmethod
    def egm96(cls, dirs: Sequence[str | Path] | None = None) -> GeoidModel:
        """EGM96 from PROJ's 15' grid :data:`EGM96_GRID`, found in ``dirs``.

        Parameters
        ----------
        dirs : sequence of path, optional
            Folders to look in; default :func:`default_grid_dirs`.

        Raises
        ------
        GeoidError
            If no folder holds the grid (the message names it and where to get it).
        """
        where = default_grid_dirs() if dirs is None else tuple(Path(d) for d in dirs)
        path = find_grid(EGM96_GRID, where)
        if path is None:
            raise GeoidError(
                f"the EGM96 geoid grid {EGM96_GRID} is not installed (looked in "
                f"{', '.join(str(d) for d in where)}); install Debian's proj-data or give "
                "the grid file itself"
            )
        return cls.from_grid(path, "EGM96")

    # ---------------------------------------------------------------- evaluation
    def _transformer(self) -> Any:
        # pyproj transformers are not shared between threads: one per thread and model.
        tr = getattr(self._local, "tr", None)
        if tr is None:
            from pyproj import Transformer
            from pyproj.exceptions import ProjError

            try:
                tr = Transformer.from_pipeline(_pipeline(self.grid_path))  # type: ignore[arg-type]
            except ProjError as exc:
                msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                where = self.grid_path
                raise GeoidError(f"PROJ cannot read the geoid grid {where}: {msg}") from None
            self._local.tr = tr
        return tr

    @property
    def orthometric(self) -> bool:
        """Whether heights through this model are above a geoid (False: ellipsoidal)."""
        return self.kind != "ellipsoidal"

    @property
    def datum(self) -> str:
        """The name of the height datum, for people: ``"EGM96 geoid"``, ``"WGS84 ellipsoid"``."""
        if self.kind == "ellipsoidal":
            return "WGS84 ellipsoid (no geoid model)"
        if self.kind == "constant":
            return f"geoid of the site (N = {self.n_m:g} m, stated)"
        return f"{self.name} geoid"

    @property
    def description(self) -> str:
        """One phrase saying how ``N`` is got (for file metadata)."""
        if self.kind == "grid":
            return f"{self.name} ({self.grid_path.name}, evaluated at each point)"  # type: ignore[union-attr]
        if self.kind == "constant":
            return f"the site's constant geoid undulation N = {self.n_m:g} m"
        return "no geoid model (N = 0)"

    def undulation_m(self, lat_deg: Any, lon_deg: Any) -> np.ndarray:
        """The undulation ``N`` (m, geoid above the WGS84 ellipsoid) at each point.

        Parameters
        ----------
        lat_deg, lon_deg : array_like
            WGS84 latitude and longitude (degrees), broadcast together.

        Returns
        -------
        ndarray
            float64, the broadcast shape.

        Raises
        ------
        GeoidError
            If a position is not finite or lies outside the grid.
        """
        lat, lon = np.broadcast_arrays(
            np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64)
        )
        if self.kind != "grid":
            return np.full(lat.shape, self.n_m)
        if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon))):
            raise GeoidError("geoid undulation asked at a position that is not finite")
        flat_lat, flat_lon = lat.ravel(), lon.ravel()
        _, _, n = self._transformer().transform(flat_lon, flat_lat, np.zeros(flat_lat.size))
        n = np.asarray(n, dtype=np.float64).reshape(lat.shape)
        bad = ~np.isfinite(n)
        if bad.any():
            k = int(np.flatnonzero(bad.ravel())[0])
            raise GeoidError(
                f"the geoid grid {self.grid_path} does not cover {int(bad.sum())} point(s),"
                f" e.g. lat {flat_lat[k]:.6f}, lon {flat_lon[k]:.6f}"
            )
        return n

    def to_orthometric(self, lat_deg: Any, lon_deg: Any, h_m: Any) -> np.ndarray:
        """``H = h - N(lat, lon)``: ellipsoidal heights ``h_m`` (m) to heights above the geoid."""
        h = np.asarray(h_m, dtype=np.float64)
        return h - self.undulation_m(lat_deg, lon_deg)

    def to_ellipsoidal(self, lat_deg: Any, lon_deg: Any, big_h_m: Any) -> np.ndarray:
        """``h = H + N(lat, lon)``: heights above the geoid ``big_h_m`` (m) to ellipsoidal."""
        big_h = np.asarray(big_h_m, dtype=np.float64)
        return big_h + self.undulation_m(lat_deg, lon_deg)


def as_geoid(value: float | GeoidModel) -> GeoidModel:
    """A :class:`GeoidModel` from a model or a constant undulation (m; 0 = ellipsoidal)."""
    if isinstance(value, GeoidModel):
        return value
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating):
        raise GeoidError(f"a geoid must be a GeoidModel or an undulation in m, got {value!r}")
    n = float(value)
    return GeoidModel.ellipsoidal() if n == 0.0 else GeoidModel.constant(n)
