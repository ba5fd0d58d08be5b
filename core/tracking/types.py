"""Value types of the tracking library: detections, ray fixes, track points, tracks.

Frames and units follow ``docs/conventions.md``: positions are in the local site frame
("ENU": x east, y north, z up, metres), times are seconds (``t_s``) since the start of the
session, pixels are ``(u, v)`` = (column, row) with ``(0, 0)`` the centre of the top-left
pixel.

The geolocation stage turns a :class:`Detection` into a :class:`Fix` (the viewing ray of
the box's foot pixel and every place it meets the terrain); the trackers turn fixes into
:class:`Track` values. Nothing here knows about cameras or DEM files.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..errors import DetectionError, TrackingError

__all__ = [
    "CLASSES",
    "Detection",
    "Fix",
    "ObjectClass",
    "Track",
    "TrackPoint",
    "TruthPath",
]

ObjectClass = Literal["vehicle", "human"]
#: The object classes the trackers know, in a fixed order.
CLASSES: tuple[str, ...] = ("vehicle", "human")


def _frozen_array(
    value: object, shape: tuple[int | None, ...], name: str, exc: type[Exception]
) -> np.ndarray:
    """Return ``value`` as a read-only float64 array of ``shape`` (None = any length)."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise exc(f"{name} must be numeric, got {value!r}") from err
    if arr.shape != shape and (
        arr.ndim != len(shape)
        or any(
            want is not None and have != want for have, want in zip(arr.shape, shape, strict=True)
        )
    ):
        raise exc(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise exc(f"{name} must be finite")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Detection:
    """One detector output: a class-labelled image box from one sensor at one time.

    Parameters
    ----------
    t_s : float
        Capture time (s).
    sensor : str
        Sensor (camera) id.
    bbox : tuple of 4 float
        ``(u_min, v_min, u_max, v_max)`` in pixels, ``u_min <= u_max``, ``v_min <= v_max``.
    cls : {"vehicle", "human"}
        Object class.
    score : float or None
        Detector confidence, if any.
    local_id : str or None
        The detector's or a 2D tracker's own id for the object, if any (not trusted).
    """

    t_s: float
    sensor: str
    bbox: tuple[float, float, float, float]
    cls: ObjectClass
    score: float | None = None
    local_id: str | None = None

    def __post_init__(self) -> None:
        if not math.isfinite(float(self.t_s)):
            raise DetectionError(f"detection time must be finite, got {self.t_s}")
        if not isinstance(self.sensor, str) or not self.sensor:
            raise DetectionError("detection sensor must be a non-empty string")
        if self.cls not in CLASSES:
            raise DetectionError(f"detection class must be one of {CLASSES}, got {self.cls!r}")
        if len(self.bbox) != 4:
            raise DetectionError(f"bbox must have 4 numbers, got {self.bbox!r}")
        box = tuple(float(b) for b in self.bbox)
        if not all(math.isfinite(b) for b in box):
            raise DetectionError(f"bbox must be finite, got {self.bbox!r}")
        if box[0] > box[2] or box[1] > box[3]:
            raise DetectionError(f"bbox must have u_min <= u_max and v_min <= v_max: {box}")
        if self.score is not None and not math.isfinite(float(self.score)):
            raise DetectionError(f"score must be finite or None, got {self.score}")
        object.__setattr__(self, "t_s", float(self.t_s))
        object.__setattr__(self, "bbox", box)
        if self.score is not None:
            object.__setattr__(self, "score", float(self.score))

    @classmethod
    def _trusted(
        cls,
        t_s: float,
        sensor: str,
        bbox: tuple[float, float, float, float],
        obj_cls: ObjectClass,
        score: float | None,
        local_id: str | None,
    ) -> Detection:
        """Internal: a detection from values already in the form ``__post_init__`` gives.

        No check: the caller guarantees what the constructor would (a finite float
        ``t_s``, a non-empty ``sensor``, a known class, a tuple of 4 finite floats in
        order, a finite float or None ``score``). For the detection readers, which check
        each record before making it.
        """
        det = object.__new__(cls)
        det.__dict__.update(
            t_s=t_s, sensor=sensor, bbox=bbox, cls=obj_cls, score=score, local_id=local_id
        )
        return det

    @property
    def foot_pixel(self) -> tuple[float, float]:
        """Bottom-centre of the box ``(u, v)`` (px): where the object meets the ground."""
        u_min, _, u_max, v_max = self.bbox
        return ((u_min + u_max) / 2.0, v_max)


@dataclass(frozen=True, eq=False)
class Fix:
    """A single-frame geolocation: one detection's viewing ray and its terrain hits.

    Parameters
    ----------
    t_s : float
        Time (s).
    sensor : str
        Sensor id (for a fused two-camera fix, ``"a+b"``).
    cls : {"vehicle", "human"}
        Object class.
    detection_index : int
        Index of the source detection in the caller's detection list.
    origin_enu : array_like, shape (3,)
        Ray origin (camera centre), local frame, m.
    direction_enu : array_like, shape (3,)
        Ray direction, local frame; normalised here.
    hits_enu : array_like, shape (k, 3)
        Every terrain hit of the ray, nearest first; ``k`` may be 0.
    hit_sigma_m : array_like, shape (k,)
        1-sigma horizontal uncertainty of each hit (m, > 0).
    road_hit_enu : array_like, shape (3,), or None
        The road rule's answer (the point of the ray on the road network), if any.
    score : float or None
        Detector confidence, copied from the detection.
    hit_cov_en_m2 : array_like, shape (k, 2, 2), or None
        Full horizontal covariance (east, north) of each hit (m^2). A hit is elongated
        along its ray's ground track (a pixel error moves it far along a grazing ray and
        little across it); None means isotropic, ``hit_sigma_m**2 * I``.
    """

    t_s: float
    sensor: str
    cls: ObjectClass
    detection_index: int
    origin_enu: np.ndarray
    direction_enu: np.ndarray
    hits_enu: np.ndarray
    hit_sigma_m: np.ndarray
    road_hit_enu: np.ndarray | None = None
    score: float | None = None
    hit_cov_en_m2: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not math.isfinite(float(self.t_s)):
            raise TrackingError(f"fix time must be finite, got {self.t_s}")
        if self.cls not in CLASSES:
            raise TrackingError(f"fix class must be one of {CLASSES}, got {self.cls!r}")
        object.__setattr__(self, "t_s", float(self.t_s))
        object.__setattr__(self, "detection_index", int(self.detection_index))
        err = TrackingError
        origin = _frozen_array(self.origin_enu, (3,), "origin_enu", err)
        direction = np.array(_frozen_array(self.direction_enu, (3,), "direction_enu", err))
        norm = float(np.linalg.norm(direction))
        if norm == 0.0:
            raise TrackingError("direction_enu must be non-zero")
        direction /= norm
        direction.setflags(write=False)
        hits = np.asarray(self.hits_enu, dtype=np.float64)
        if hits.size == 0:
            hits = np.zeros((0, 3))
        hits = _frozen_array(hits, (None, 3), "hits_enu", err)
        sigma = _frozen_array(np.atleast_1d(self.hit_sigma_m), (hits.shape[0],), "hit_sigma_m", err)
        if np.any(sigma <= 0):
            raise TrackingError("hit_sigma_m must be positive")
        road = None
        if self.road_hit_enu is not None:
            road = _frozen_array(self.road_hit_enu, (3,), "road_hit_enu", err)
        object.__setattr__(self, "origin_enu", origin)
        object.__setattr__(self, "direction_enu", direction)
        object.__setattr__(self, "hits_enu", hits)
        object.__setattr__(self, "hit_sigma_m", sigma)
        object.__setattr__(self, "road_hit_enu", road)
        if self.hit_cov_en_m2 is not None:
            cov = np.asarray(self.hit_cov_en_m2, dtype=np.float64)
            if cov.size == 0 and hits.shape[0] == 0:
                cov = np.zeros((0, 2, 2))
            cov = _frozen_array(cov, (hits.shape[0], 2, 2), "hit_cov_en_m2", err)
            sym = 0.5 * (cov + np.swapaxes(cov, 1, 2))
            det = sym[:, 0, 0] * sym[:, 1, 1] - sym[:, 0, 1] ** 2
            if np.any(sym[:, 0, 0] <= 0) or np.any(det <= 0):
                raise TrackingError("hit_cov_en_m2 must be symmetric positive definite")
            sym.setflags(write=False)
            object.__setattr__(self, "hit_cov_en_m2", sym)

    @classmethod
    def _trusted(
        cls,
        t_s: float,
        sensor: str,
        obj_cls: ObjectClass,
        detection_index: int,
        origin_enu: np.ndarray,
        direction_enu: np.ndarray,
        hits_enu: np.ndarray,
        hit_sigma_m: np.ndarray,
        road_hit_enu: np.ndarray | None,
        score: float | None,
        hit_cov_en_m2: np.ndarray | None,
    ) -> Fix:
        """Internal: a fix from values already in the form ``__post_init__`` gives.

        No copy and no check: the caller guarantees what the public constructor would
        (float ``t_s``, a known class, int index, read-only finite float64 arrays of the
        documented shapes, a unit ``direction_enu``, positive ``hit_sigma_m``, symmetric
        positive definite ``hit_cov_en_m2``). For :meth:`from_arrays` (the one
        public way to make many fixes at once) and the fusion of ``core.tracking``, which
        check whole arrays first.
        """
        fix = object.__new__(cls)
        # the instance dict filled at once (what object.__setattr__ per field does, at a
        # fraction of the cost: the builders make tens of thousands of fixes a second)
        fix.__dict__.update(
            t_s=t_s,
            sensor=sensor,
            cls=obj_cls,
            detection_index=detection_index,
            origin_enu=origin_enu,
            direction_enu=direction_enu,
            hits_enu=hits_enu,
            hit_sigma_m=hit_sigma_m,
            road_hit_enu=road_hit_enu,
            score=score,
            hit_cov_en_m2=hit_cov_en_m2,
        )
        return fix

    @classmethod
    def from_arrays(
        cls,
        t_s: Sequence[float],
        sensor: Sequence[str],
        obj_cls: Sequence[str],
        detection_index: Sequence[int],
        origin_enu: object,
        direction_enu: object,
        hit_offsets: object,
        hits_enu: object,
        hit_sigma_m: object,
        road_hit_enu: object | None = None,
        has_road: object | None = None,
        score: Sequence[float | None] | None = None,
        hit_cov_en_m2: object | None = None,
        has_cov: object | None = None,
    ) -> list[Fix]:
        """Many fixes from stacked arrays, validated once over the whole arrays.

        The fixes the public constructor makes of each row (same arithmetic, bit for
        bit: the direction normalised, the covariances symmetrised), without its
        per-fix copies and checks. When a check over the arrays fails, every fix goes
        through the constructor, which names the problem (:class:`TrackingError`).

        Parameters
        ----------
        t_s, sensor, obj_cls, detection_index : sequence, length n
            Per fix: time (s), sensor id, class, detection index.
        origin_enu, direction_enu : array_like, shape (n, 3)
            Ray origins and (not necessarily unit) directions, local frame (m).
        hit_offsets : array_like of int, shape (n + 1,)
            Fix ``r``'s hits are rows ``hit_offsets[r]:hit_offsets[r + 1]`` of the hit
            arrays (non-decreasing, from 0 to ``k``).
        hits_enu : array_like, shape (k, 3)
            Every fix's terrain hits, nearest first, local frame (m).
        hit_sigma_m : array_like, shape (k,)
            1-sigma horizontal uncertainty of each hit (m, > 0).
        road_hit_enu : array_like, shape (n, 3), optional
            Road-rule points; rows where ``has_road`` is false are not read.
        has_road : array_like of bool, shape (n,), optional
            Which fixes have a road point (default: all, when ``road_hit_enu`` is given).
        score : sequence of float or None, length n, optional
            Detector confidences (default: None for every fix).
        hit_cov_en_m2 : array_like, shape (k, 2, 2), optional
            Horizontal covariance of each hit (m^2).
        has_cov : array_like of bool, shape (n,), optional
            Which fixes carry covariances (default: all, when ``hit_cov_en_m2`` is given);
            the covariance rows of the others are not read.

        Returns
        -------
        list of Fix
            One per row, in row order.
        """
        n = len(t_s)
        rows = _FixRows.of(
            n, origin_enu, direction_enu, hit_offsets, hits_enu, hit_sigma_m,
            road_hit_enu, has_road, hit_cov_en_m2, has_cov,
        )  # fmt: skip
        scores = [None] * n if score is None else list(score)
        try:
            times_ok = bool(np.isfinite(np.asarray(t_s, dtype=np.float64)).all())
        except (TypeError, ValueError):
            times_ok = False
        if (
            rows is None
            or not times_ok
            or len(sensor) != n
            or len(obj_cls) != n
            or len(detection_index) != n
            or len(scores) != n
            or not all(c in CLASSES for c in obj_cls)
            or not all(isinstance(s, str) for s in sensor)
        ):
            return _checked_fixes(
                t_s, sensor, obj_cls, detection_index, origin_enu, direction_enu,
                hit_offsets, hits_enu, hit_sigma_m, road_hit_enu, has_road, scores,
                hit_cov_en_m2, has_cov,
            )  # fmt: skip
        out: list[Fix] = []
        offsets = rows.offsets.tolist()
        d_all = rows.direction
        for r in range(n):
            lo, hi = offsets[r], offsets[r + 1]
            out.append(
                cls._trusted(
                    float(t_s[r]),
                    sensor[r],
                    obj_cls[r],  # type: ignore[arg-type]
                    int(detection_index[r]),
                    rows.origin[r],
                    _unit(d_all[r]),
                    rows.hits[lo:hi],
                    rows.sigma[lo:hi],
                    rows.road[r] if rows.has_road[r] else None,
                    scores[r],
                    rows.cov[lo:hi] if rows.cov is not None and rows.has_cov[r] else None,
                )
            )
        return out

    def reindexed(self, detection_index: int) -> Fix:
        """The same fix under another detection index, as :meth:`from_arrays` remakes it.

        The fix :meth:`from_arrays` gives of this fix's own values (its direction
        normalised once more, its covariances symmetrised once more: a no-op), bit for
        bit, without the stacking and checks: what a stored fix body gives back when the
        fix has hits. The arrays are shared (they are read-only).
        """
        return Fix._trusted(
            self.t_s,
            self.sensor,
            self.cls,
            int(detection_index),
            self.origin_enu,
            _unit(self.direction_enu),
            self.hits_enu,
            self.hit_sigma_m,
            self.road_hit_enu,
            self.score,
            self.hit_cov_en_m2,
        )

    @property
    def n_hits(self) -> int:
        """Number of terrain hits ``k``."""
        return int(self.hits_enu.shape[0])

    def hit_covariances(self) -> np.ndarray:
        """Horizontal covariance of every hit, shape (k, 2, 2) (m^2)."""
        if self.hit_cov_en_m2 is not None:
            return self.hit_cov_en_m2
        return self.hit_sigma_m[:, None, None] ** 2 * np.eye(2)[None]


def _unit(d: np.ndarray) -> np.ndarray:
    """``d`` (shape (3,), contiguous float64) over its length, read-only.

    The stacked fix constructor's normalisation (one arithmetic, so a re-made fix keeps
    every bit).
    """
    # np.linalg.norm of a 1-D float array is sqrt(x.dot(x)): the same bits, one call
    norm = math.sqrt(d.dot(d))
    if norm == 0.0:
        raise TrackingError("direction_enu must be non-zero")
    unit = d / norm
    unit.setflags(write=False)
    return unit


@dataclass(frozen=True, eq=False)
class _FixRows:
    """The arrays of :meth:`Fix.from_arrays`, checked as wholes (read-only float64)."""

    offsets: np.ndarray
    origin: np.ndarray
    direction: np.ndarray
    hits: np.ndarray
    sigma: np.ndarray
    road: np.ndarray
    has_road: np.ndarray
    cov: np.ndarray | None
    has_cov: np.ndarray

    @classmethod
    def of(
        cls,
        n: int,
        origin_enu: object,
        direction_enu: object,
        hit_offsets: object,
        hits_enu: object,
        hit_sigma_m: object,
        road_hit_enu: object | None,
        has_road: object | None,
        hit_cov_en_m2: object | None,
        has_cov: object | None,
    ) -> _FixRows | None:
        """The checked arrays, or None when any check the constructor makes would fail."""
        try:
            origin = np.asarray(origin_enu, dtype=np.float64).reshape(-1, 3)
            d = np.asarray(direction_enu, dtype=np.float64).reshape(-1, 3)
            offsets = np.asarray(hit_offsets, dtype=np.int64).reshape(-1)
            hits = np.asarray(hits_enu, dtype=np.float64).reshape(-1, 3)
            sigma = np.asarray(hit_sigma_m, dtype=np.float64).reshape(-1)
            road = (
                np.zeros((n, 3))
                if road_hit_enu is None
                else np.asarray(road_hit_enu, dtype=np.float64).reshape(-1, 3)
            )
            with_road = np.broadcast_to(
                np.asarray(road_hit_enu is not None if has_road is None else has_road, dtype=bool),
                (n,),
            )
            cov = (
                None
                if hit_cov_en_m2 is None
                else np.asarray(hit_cov_en_m2, dtype=np.float64).reshape(-1, 2, 2)
            )
            with_cov = np.broadcast_to(
                np.asarray(cov is not None if has_cov is None else has_cov, dtype=bool), (n,)
            )
        except (TypeError, ValueError):
            return None
        k = len(hits)
        if (
            len(origin) != n
            or len(d) != n
            or offsets.shape != (n + 1,)
            or len(road) != n
            or len(sigma) != k
            or (cov is not None and len(cov) != k)
            or (n and (offsets[0] != 0 or offsets[-1] != k or np.any(np.diff(offsets) < 0)))
            or (not n and k)
        ):
            return None
        cov_rows = np.repeat(with_cov, np.diff(offsets)) if n else np.zeros(0, dtype=bool)
        if not (
            np.isfinite(origin).all()
            and np.isfinite(d).all()
            and np.isfinite(hits).all()
            and np.isfinite(sigma).all()
            and np.isfinite(road[with_road]).all()
        ) or np.any(sigma <= 0):
            return None
        sym = None
        if cov is not None:
            used = cov[cov_rows]
            if not np.isfinite(used).all():
                return None
            sym = 0.5 * (cov + np.swapaxes(cov, 1, 2))
            s = sym[cov_rows]
            det = s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] ** 2
            if np.any(s[:, 0, 0] <= 0) or np.any(det <= 0):
                return None
            sym.setflags(write=False)
        for arr in (origin, hits, sigma, road):
            arr.setflags(write=False)
        return cls(offsets, origin, d, hits, sigma, road, with_road, sym, with_cov)


def _checked_fixes(
    t_s: Sequence[float],
    sensor: Sequence[str],
    obj_cls: Sequence[str],
    detection_index: Sequence[int],
    origin_enu: object,
    direction_enu: object,
    hit_offsets: object,
    hits_enu: object,
    hit_sigma_m: object,
    road_hit_enu: object | None,
    has_road: object | None,
    score: Sequence[float | None],
    hit_cov_en_m2: object | None,
    has_cov: object | None,
) -> list[Fix]:
    """:meth:`Fix.from_arrays` through the validating constructor, fix by fix."""
    n = len(t_s)
    try:
        offsets = np.asarray(hit_offsets, dtype=np.int64).reshape(-1)
        origin = np.asarray(origin_enu, dtype=object).reshape(-1, 3)
        d = np.asarray(direction_enu, dtype=object).reshape(-1, 3)
        hits = np.asarray(hits_enu, dtype=object).reshape(-1, 3)
        sigma = np.asarray(hit_sigma_m, dtype=object).reshape(-1)
        road = None if road_hit_enu is None else np.asarray(road_hit_enu, dtype=object)
        road = None if road is None else road.reshape(-1, 3)
        cov = None if hit_cov_en_m2 is None else np.asarray(hit_cov_en_m2, dtype=object)
        cov = None if cov is None else cov.reshape(-1, 2, 2)
    except (TypeError, ValueError) as err:
        raise TrackingError(f"fix arrays are malformed: {err}") from err
    if offsets.shape != (n + 1,) or not (len(origin) == len(d) == len(sensor) == n):
        raise TrackingError(f"fix arrays must hold {n} fixes (hit_offsets: {n + 1} entries)")
    with_road = np.broadcast_to(
        np.asarray(road is not None if has_road is None else has_road, dtype=bool), (n,)
    )
    with_cov = np.broadcast_to(
        np.asarray(cov is not None if has_cov is None else has_cov, dtype=bool), (n,)
    )
    out = []
    for r in range(n):
        lo, hi = int(offsets[r]), int(offsets[r + 1])
        out.append(
            Fix(
                t_s=t_s[r],
                sensor=sensor[r],
                cls=obj_cls[r],  # type: ignore[arg-type]
                detection_index=detection_index[r],
                origin_enu=origin[r],
                direction_enu=d[r],
                hits_enu=hits[lo:hi],
                hit_sigma_m=sigma[lo:hi],
                road_hit_enu=road[r] if road is not None and with_road[r] else None,
                score=score[r],
                hit_cov_en_m2=cov[lo:hi] if cov is not None and with_cov[r] else None,
            )
        )
    return out


@dataclass(frozen=True, eq=False)
class TrackPoint:
    """One estimate of a track, made when fixes were associated to it.

    Parameters
    ----------
    t_s : float
        Time (s).
    p_enu : ndarray, shape (3,)
        Estimated position, local frame (m); ``z`` comes from the hit used.
    sensors : tuple of str
        Sensors whose fixes made this point.
    fix_indices : tuple of int
        Indices of those fixes in the order the tracker received them (``run_tracker``:
        positions in its ``fixes`` argument).
    cov_xy : ndarray, shape (2, 2), or None
        Horizontal covariance of the estimate (m^2), when the method has one.
    """

    t_s: float
    p_enu: np.ndarray
    sensors: tuple[str, ...]
    fix_indices: tuple[int, ...]
    cov_xy: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "t_s", float(self.t_s))
        object.__setattr__(self, "p_enu", _frozen_array(self.p_enu, (3,), "p_enu", TrackingError))
        if self.cov_xy is not None:
            cov = _frozen_array(self.cov_xy, (2, 2), "cov_xy", TrackingError)
            object.__setattr__(self, "cov_xy", cov)
        object.__setattr__(self, "sensors", tuple(self.sensors))
        object.__setattr__(self, "fix_indices", tuple(int(i) for i in self.fix_indices))

    @classmethod
    def _made(
        cls,
        t_s: float,
        p_enu: np.ndarray,
        sensors: tuple[str, ...],
        fix_indices: tuple[int, ...],
        cov_xy: np.ndarray | None,
    ) -> TrackPoint:
        """Internal: a point from a filter's fresh estimate, checked the cheap way.

        ``p_enu`` (3,) and ``cov_xy`` (2, 2) float64 arrays (copied, as the constructor
        does); ``sensors`` and ``fix_indices`` tuples of str and int (a tracker's
        :class:`~.protocols.Measurement` fields). Anything else, or a non-finite value,
        goes through the public constructor, which says what is wrong.
        """
        if (
            p_enu.shape != (3,)
            or p_enu.dtype != np.float64
            or (cov_xy is not None and (cov_xy.shape != (2, 2) or cov_xy.dtype != np.float64))
            # a sum is finite only if every term is (an overflow just takes the long way)
            or not math.isfinite(sum(p_enu.tolist()))
            or (cov_xy is not None and not math.isfinite(sum(cov_xy.ravel().tolist())))
        ):
            return cls(t_s, p_enu, sensors, fix_indices, cov_xy)
        p_enu = p_enu.copy()
        p_enu.setflags(write=False)
        if cov_xy is not None:
            cov_xy = cov_xy.copy()
            cov_xy.setflags(write=False)
        point = object.__new__(cls)
        point.__dict__.update(
            t_s=float(t_s),
            p_enu=p_enu,
            sensors=tuple(sensors),
            fix_indices=tuple(map(int, fix_indices)),
            cov_xy=cov_xy,
        )
        return point

    def _moved(self, p_enu: np.ndarray) -> TrackPoint:
        """Internal: this point at another position ``p_enu`` (3,), float64 (m).

        Checks only what the new position brings (finite); time, sensors, indices and
        covariance are this point's, already checked.
        """
        if p_enu.shape != (3,) or p_enu.dtype != np.float64:
            return TrackPoint(self.t_s, p_enu, self.sensors, self.fix_indices, self.cov_xy)
        if not np.isfinite(p_enu).all():
            raise TrackingError("p_enu must be finite")
        p_enu.setflags(write=False)
        return self._moved_trusted(p_enu)

    def _moved_trusted(self, p_enu: np.ndarray) -> TrackPoint:
        """Internal: :meth:`_moved` of a read-only finite float64 (3,) ``p_enu``, unchecked."""
        point = object.__new__(TrackPoint)
        state = point.__dict__
        state.update(self.__dict__)
        state["p_enu"] = p_enu
        return point


@dataclass(frozen=True, eq=False)
class Track:
    """A confirmed track: one identity over time.

    Parameters
    ----------
    id : int
        Track id (>= 1, in order of confirmation).
    cls : {"vehicle", "human"}
        Object class.
    points : tuple of TrackPoint
        Estimates in time order.
    sensors : frozenset of str
        Every sensor that contributed.
    gaps : tuple of (float, float)
        ``(t_start, t_end)`` intervals longer than the gap threshold with no associated fix:
        nothing saw the object there, and the track says so instead of drawing through.
    """

    id: int
    cls: ObjectClass
    points: tuple[TrackPoint, ...]
    sensors: frozenset[str] = field(default_factory=frozenset)
    gaps: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", tuple(self.points))
        object.__setattr__(self, "sensors", frozenset(self.sensors))
        object.__setattr__(self, "gaps", tuple((float(a), float(b)) for a, b in self.gaps))

    # A Track is an immutable value, read many times per batch by the live server (a long
    # track's arrays cost O(points) to stack): built once, cached, read-only.
    @functools.cached_property
    def t_s(self) -> np.ndarray:
        """Point times, shape (n,) (s); read-only."""
        t = np.array([p.t_s for p in self.points], dtype=np.float64)
        t.setflags(write=False)
        return t

    @functools.cached_property
    def p_enu(self) -> np.ndarray:
        """Point positions, shape (n, 3), local frame (m); read-only."""
        p = np.stack([p.p_enu for p in self.points]) if self.points else np.zeros((0, 3))
        p.setflags(write=False)
        return p


@dataclass(frozen=True, eq=False)
class TruthPath:
    """The true path of one target (for metrics and synthetic scenarios).

    Parameters
    ----------
    target_id : int
        Target id.
    cls : {"vehicle", "human"}
        Object class.
    t_s : array_like, shape (n,)
        Strictly increasing times (s).
    p_enu : array_like, shape (n, 3)
        True positions, local frame (m); linear in between samples.
    """

    target_id: int
    cls: ObjectClass
    t_s: np.ndarray
    p_enu: np.ndarray

    def __post_init__(self) -> None:
        t = _frozen_array(np.atleast_1d(self.t_s), (None,), "t_s", TrackingError)
        p = _frozen_array(self.p_enu, (t.shape[0], 3), "p_enu", TrackingError)
        if t.shape[0] < 1 or np.any(np.diff(t) <= 0):
            raise TrackingError("truth times must be non-empty and strictly increasing")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "p_enu", p)

    def at(self, t_s: float | Sequence[float] | np.ndarray) -> np.ndarray:
        """Interpolate the true position at ``t_s`` (shape (m,) -> (m, 3)); NaN outside."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        out = np.stack([np.interp(t, self.t_s, self.p_enu[:, j]) for j in range(3)], axis=-1)
        outside = (t < self.t_s[0]) | (t > self.t_s[-1])
        out[outside] = np.nan
        return out
