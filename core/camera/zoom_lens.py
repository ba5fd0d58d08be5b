"""Zoom lenses: intrinsics as a function of the horizontal field of view.

A PTZ camera reports its zoom; demtrack takes it as the **horizontal field of view**
``hfov_deg`` (ONVIF's normalised zoom or a focal length are converted by the adapter).
Two ways to turn it into :class:`~demtrack.core.camera.pinhole.Intrinsics`:

Without a calibration table (:func:`intrinsics_for_hfov` with ``zoom=None``)
    The ideal zoom: ``fx = (width / 2) / tan(hfov / 2)``, ``fy = fx * base.fy / base.fx``
    (the pixel aspect of the calibrated lens), principal point and distortion those of
    the calibrated lens ``base``.

With a table (:class:`ZoomTable`, stored in ``site.json`` as ``"zoom_table"``)
    Calibrations at several zooms, each labelled by the hfov the camera *reports* there
    (its own fx need not give exactly that hfov). Between two neighbouring entries at
    ``h0 < h < h1`` with ``a = (h - h0) / (h1 - h0)``:

    * focal lengths are interpolated *tan-consistently*: the ratio of the entry's focal
      length to the ideal one, ``r = fx / f_ideal(h)`` with
      ``f_ideal(h) = (width / 2) / tan(h / 2)``, is linear in ``a`` and
      ``fx(h) = f_ideal(h) * r(a)`` (same for fy). A table of ideal lenses thus gives
      the ideal lens at every zoom, and focal length varies as ``1 / tan`` between
      entries, as a zoom's does, instead of linearly;
    * ``cx, cy`` and every distortion coefficient are linear in ``a``;
    * at an entry's own hfov the entry comes back exactly.

    An hfov outside the table's range raises :class:`~demtrack.core.errors.PoseError`:
    a lens is not extrapolated.

Many zooms at once (:meth:`ZoomTable.pixel_lenses`)
    A head that zooms continuously reports a new hfov with every frame; building (and
    checking) an :class:`Intrinsics` per hfov costs about a millisecond with distortion.
    :meth:`ZoomTable.pixel_lenses` evaluates the same interpolation for an array of hfovs
    in one pass (:class:`PixelLenses`: per-pixel fx, fy, cx, cy, coefficients and radial
    fold radius), for one vectorised undistortion
    (:mod:`~demtrack.core.geolocation.posed_rays`). Its values equal
    :meth:`ZoomTable.intrinsics_at`'s to round-off (a few ulps). Of the lens checks it
    keeps the radial one (the model must not fold inside the image's corner radius, the
    same test as :class:`Intrinsics`); the grid check for tangential folds becomes a
    per-pixel one (the pixel's own undistortion must converge with a positive Jacobian).
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..errors import PoseError
from .lens import _R_FOLD_MAX
from .pinhole import Intrinsics

__all__ = [
    "PixelLenses",
    "ZoomEntry",
    "ZoomTable",
    "fold_radii",
    "ideal_focal_px",
    "intrinsics_for_hfov",
]

_ENTRY_KEYS = ("hfov_deg", "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4")
_LINEAR = ("cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4")


def _hfov(value: Any, name: str = "hfov_deg") -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise PoseError(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(out) and 0.0 < out < 180.0):
        raise PoseError(f"{name} must be a finite angle in (0, 180) degrees, got {value!r}")
    return out


def ideal_focal_px(width_px: int, hfov_deg: float) -> float:
    """Focal length (px) of an ideal pinhole whose image ``width_px`` spans ``hfov_deg``."""
    return 0.5 * width_px / math.tan(math.radians(_hfov(hfov_deg)) / 2.0)


@dataclass(frozen=True)
class ZoomEntry:
    """The lens calibrated at one zoom.

    Parameters
    ----------
    hfov_deg : float
        The horizontal field of view the camera reports at this zoom (degrees, (0, 180)).
    fx, fy, cx, cy : float
        Focal lengths and principal point (px; pixel (0, 0) the centre of the top-left
        pixel), as :class:`~demtrack.core.camera.pinhole.Intrinsics`.
    k1, k2, p1, p2, k3, k4 : float
        Distortion coefficients (OpenCV's, plus the ``r^8`` term ``k4``).
    """

    hfov_deg: float
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "hfov_deg", _hfov(self.hfov_deg))
        for f in fields(self)[1:]:
            value = getattr(self, f.name)
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise PoseError(f"zoom entry {f.name} must be a number, got {value!r}") from None
            if not math.isfinite(number):
                raise PoseError(f"zoom entry {f.name} must be finite, got {value!r}")
            object.__setattr__(self, f.name, number)
        if self.fx <= 0.0 or self.fy <= 0.0:
            raise PoseError(f"zoom entry focal lengths must be positive, got {self.fx}, {self.fy}")

    def to_dict(self) -> dict[str, float]:
        """``{hfov_deg, fx, fy, cx, cy, k1, k2, p1, p2, k3}`` (``k4`` only when non-zero)."""
        out = {k: getattr(self, k) for k in _ENTRY_KEYS}
        if out["k4"] == 0.0:
            del out["k4"]
        return out

    def intrinsics(self, base: Intrinsics) -> Intrinsics:
        """The entry's lens on ``base``'s image size."""
        return Intrinsics(
            self.fx, self.fy, self.cx, self.cy, base.width, base.height,
            self.k1, self.k2, self.p1, self.p2, self.k3, self.k4,
        )  # fmt: skip


@dataclass(frozen=True)
class ZoomTable:
    """A zoom lens's calibrations at several zooms (see the module notes).

    Parameters
    ----------
    entries : sequence of ZoomEntry
        At least one; sorted by ``hfov_deg`` here, which must not repeat.
    """

    entries: tuple[ZoomEntry, ...]

    def __post_init__(self) -> None:
        entries = tuple(self.entries)
        if not entries:
            raise PoseError("a zoom table needs at least one entry")
        if not all(isinstance(e, ZoomEntry) for e in entries):
            raise PoseError("zoom table entries must be ZoomEntry values")
        entries = tuple(sorted(entries, key=lambda e: e.hfov_deg))
        for a, b in zip(entries, entries[1:], strict=False):
            if a.hfov_deg == b.hfov_deg:
                raise PoseError(f"zoom table has two entries at hfov {a.hfov_deg} deg")
        object.__setattr__(self, "entries", entries)

    @property
    def hfov_range_deg(self) -> tuple[float, float]:
        """Smallest and largest hfov of the table (degrees)."""
        return self.entries[0].hfov_deg, self.entries[-1].hfov_deg

    def intrinsics_at(self, hfov_deg: float, base: Intrinsics) -> Intrinsics:
        """The lens at ``hfov_deg``, on ``base``'s image size (rules in the module notes).

        Raises
        ------
        PoseError
            For an hfov outside the table's range, or one that is not a finite angle.
        """
        h = _hfov(hfov_deg)
        lo, hi = self.hfov_range_deg
        if not lo <= h <= hi:
            raise PoseError(
                f"zoom hfov {h:g} deg is outside the lens's calibration table "
                f"({lo:g} .. {hi:g} deg)"
            )
        hs = [e.hfov_deg for e in self.entries]
        k = bisect.bisect_left(hs, h)
        if hs[k] == h:
            return self.entries[k].intrinsics(base)
        e0, e1 = self.entries[k - 1], self.entries[k]
        a = (h - e0.hfov_deg) / (e1.hfov_deg - e0.hfov_deg)
        w = base.width
        f0, f1, f = (ideal_focal_px(w, x) for x in (e0.hfov_deg, e1.hfov_deg, h))

        def lin(name: str) -> float:
            v0, v1 = getattr(e0, name), getattr(e1, name)
            return v0 + a * (v1 - v0)

        def focal(name: str) -> float:
            r0, r1 = getattr(e0, name) / f0, getattr(e1, name) / f1
            return f * (r0 + a * (r1 - r0))

        values = {name: lin(name) for name in _LINEAR}
        return Intrinsics(
            focal("fx"), focal("fy"), values["cx"], values["cy"], base.width, base.height,
            values["k1"], values["k2"], values["p1"], values["p2"], values["k3"], values["k4"],
        )  # fmt: skip

    def pixel_lenses(self, hfov_deg: np.ndarray, base: Intrinsics) -> PixelLenses:
        """The lenses at many zooms at once (module notes), on ``base``'s image size.

        Parameters
        ----------
        hfov_deg : ndarray, shape (k,)
            Horizontal fields of view (degrees).
        base : Intrinsics
            The calibrated lens (its image size).

        Returns
        -------
        PixelLenses
            ``valid`` is False where the hfov is not finite, lies outside the table, or
            the lens there folds inside the image (its other arrays are then NaN).
        """
        h = np.asarray(hfov_deg, dtype=np.float64).reshape(-1)
        table = np.array([[getattr(e, k) for k in _ENTRY_KEYS] for e in self.entries])
        lo, hi = self.hfov_range_deg
        inside = np.isfinite(h) & (h >= lo) & (h <= hi) & (h > 0.0) & (h < 180.0)
        hs = table[:, 0]
        hh = np.where(inside, h, lo)
        if len(hs) == 1:
            vals = np.repeat(table[:1, 1:], len(h), axis=0)
        else:
            k = np.clip(np.searchsorted(hs, hh, side="left"), 1, len(hs) - 1)
            e0, e1 = table[k - 1], table[k]
            a = ((hh - e0[:, 0]) / (e1[:, 0] - e0[:, 0]))[:, None]
            vals = e0[:, 1:] + a * (e1[:, 1:] - e0[:, 1:])
            w = base.width

            def ideal(x: np.ndarray) -> np.ndarray:
                return 0.5 * w / np.tan(np.radians(x) / 2.0)

            f0, f1, f = ideal(e0[:, 0]), ideal(e1[:, 0]), ideal(hh)
            for j in (0, 1):  # fx, fy: tan-consistent
                r0, r1 = e0[:, 1 + j] / f0, e1[:, 1 + j] / f1
                vals[:, j] = f * (r0 + a[:, 0] * (r1 - r0))
            exact = hs[k] == hh  # an entry's own hfov: the entry itself
            vals[exact] = e1[exact, 1:]
        fx, fy, cx, cy = vals[:, 0], vals[:, 1], vals[:, 2], vals[:, 3]
        coeffs = vals[:, 4:]
        k1, k2, _, _, k3, k4 = coeffs.T
        fold = fold_radii(k1, k2, k3, k4)
        # The radial check of Intrinsics: no fold inside the image's corner radius.
        uc = np.array([-0.5, base.width - 0.5])
        vc = np.array([-0.5, base.height - 0.5])
        du = np.max(np.abs(uc[None] - cx[:, None]), axis=1) / fx
        dv = np.max(np.abs(vc[None] - cy[:, None]), axis=1) / fy
        s = fold * fold
        with np.errstate(invalid="ignore", over="ignore"):
            rho = fold * (1.0 + s * (k1 + s * (k2 + s * (k3 + s * k4))))
        flat = ~np.isfinite(fold)
        valid = inside & (flat | (rho > np.hypot(du, dv)))
        out = np.where(valid[:, None], np.column_stack([vals, fold]), np.nan)
        return PixelLenses(
            out[:, 0], out[:, 1], out[:, 2], out[:, 3], out[:, 4:10], out[:, 10], valid
        )

    def to_list(self) -> list[dict[str, float]]:
        """JSON-ready rows, sorted by hfov (what ``site.json`` stores as ``zoom_table``)."""
        return [e.to_dict() for e in self.entries]

    @classmethod
    def from_list(cls, rows: Iterable[Mapping[str, Any]]) -> ZoomTable:
        """Inverse of :meth:`to_list`; distortion keys may be omitted (zero).

        Raises
        ------
        PoseError
            On a row that is not a mapping, has unknown or missing keys, or bad values.
        """
        if isinstance(rows, str | bytes) or not isinstance(rows, Iterable):
            raise PoseError("zoom_table must be a list of rows")
        entries = []
        for k, row in enumerate(rows):
            if not isinstance(row, Mapping):
                raise PoseError(f"zoom_table row {k} must be an object")
            unknown = sorted(set(row) - set(_ENTRY_KEYS))
            missing = [key for key in _ENTRY_KEYS[:5] if key not in row]
            if unknown or missing:
                raise PoseError(
                    f"zoom_table row {k}: missing keys {missing}, unknown keys {unknown}"
                )
            entries.append(ZoomEntry(**row))
        return cls(tuple(entries))


def intrinsics_for_hfov(
    base: Intrinsics, hfov_deg: float, zoom: ZoomTable | None = None
) -> Intrinsics:
    """The lens at zoom ``hfov_deg``: from ``zoom``'s table, else the ideal zoom of ``base``.

    Parameters
    ----------
    base : Intrinsics
        The calibrated lens (image size; without a table also aspect, principal point
        and distortion).
    hfov_deg : float
        Horizontal field of view (degrees, (0, 180)).
    zoom : ZoomTable, optional
        The lens's calibration table.

    Raises
    ------
    PoseError
        For an hfov that is not in (0, 180), or outside the table.
    """
    if zoom is not None:
        return _table_lens(zoom, float(hfov_deg), base)
    fx = ideal_focal_px(base.width, hfov_deg)
    return Intrinsics(
        fx, fx * (base.fy / base.fx), base.cx, base.cy, base.width, base.height,
        *base.lens_coeffs,
    )  # fmt: skip


@functools.lru_cache(maxsize=512)
def _table_lens(zoom: ZoomTable, hfov_deg: float, base: Intrinsics) -> Intrinsics:
    """:meth:`ZoomTable.intrinsics_at`, kept for the zooms last asked for.

    A lens is checked for invertibility when it is built (about a millisecond with
    distortion); a head holds its zoom for many frames, so the same few come back.
    """
    return zoom.intrinsics_at(hfov_deg, base)


@dataclass(frozen=True, eq=False)
class PixelLenses:
    """One lens per pixel (:meth:`ZoomTable.pixel_lenses`); arrays of shape (k,).

    Parameters
    ----------
    fx, fy, cx, cy : ndarray
        Focal lengths and principal points (px).
    coeffs : ndarray, shape (k, 6)
        ``(k1, k2, p1, p2, k3, k4)`` per pixel.
    fold_radius : ndarray
        Undistorted normalised radius of the radial fold (``inf``: none).
    valid : ndarray of bool
        Where a lens exists (inside the table, no fold inside the image).
    """

    fx: np.ndarray
    fy: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    coeffs: np.ndarray
    fold_radius: np.ndarray
    valid: np.ndarray

    def take(self, rows: np.ndarray) -> PixelLenses:
        """The lenses of ``rows`` (an index or mask array)."""
        return PixelLenses(
            *(getattr(self, f.name)[rows] for f in fields(self))  # type: ignore[arg-type]
        )


def fold_radii(k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, k4: np.ndarray) -> np.ndarray:
    """:func:`~demtrack.core.camera.lens.radial_fold_radius` for arrays of coefficients.

    The same trimming of negligible leading terms and the same companion-matrix roots
    (what ``np.roots`` does), batched by polynomial degree.
    """
    c = np.column_stack([9.0 * k4, 7.0 * k3, 5.0 * k2, 3.0 * k1, np.ones(len(k1))])
    deg = np.zeros(len(c), dtype=np.int64)
    for j in range(4):  # the degree: the first leading term that is not negligible
        d = 4 - j
        keep = (deg == 0) & ~(np.abs(c[:, j]) * _R_FOLD_MAX ** (2 * d) < 1e-12)
        deg[keep] = d
    out = np.full(len(c), np.inf)
    for d in range(1, 5):
        rows = np.flatnonzero(deg == d)
        if not len(rows):
            continue
        p = c[rows, 4 - d :]
        comp = np.zeros((len(rows), d, d))
        comp[:, 0, :] = -p[:, 1:] / p[:, :1]
        if d > 1:
            comp[:, np.arange(1, d), np.arange(d - 1)] = 1.0
        roots = np.linalg.eigvals(comp)
        tol = 1e-7 * np.maximum(1.0, np.abs(roots))
        real = (np.abs(roots.imag) <= tol) & (roots.real > 0.0)
        s = np.where(real, roots.real, np.inf).min(axis=1)
        out[rows] = np.sqrt(s)
    return out
