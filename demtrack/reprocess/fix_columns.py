"""Fixes as stacked columns: what geolocation tasks hand to tracking tasks and to Parquet.

A list of :class:`~demtrack.core.tracking.types.Fix` pickles into one small object per
array; the same fixes as a handful of stacked arrays cross a process boundary in one
piece. :meth:`FixColumns.to_fixes` makes the fixes back with
:meth:`~demtrack.core.tracking.types.Fix.from_arrays`; every engine goes through the same
columns, so their fixes are the same bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from demtrack.core.tracking.types import Fix

__all__ = ["FixColumns"]


@dataclass(frozen=True)
class FixColumns:
    """``n`` fixes with ``k`` hits in all, as arrays.

    Attributes
    ----------
    det_id : ndarray of int64, shape (n,)
        The source detection's id (its place in the archive's canonical order).
    t_s : ndarray, shape (n,)
        Time, UNIX s.
    sensor, cls : ndarray of str (object), shape (n,)
    origin_enu, direction_enu : ndarray, shape (n, 3)
        Ray origin and unit direction, site frame (m).
    hit_offsets : ndarray of int64, shape (n + 1,)
        Fix ``r``'s hits are rows ``hit_offsets[r]:hit_offsets[r + 1]``.
    hits_enu : ndarray, shape (k, 3)
    hit_sigma_m : ndarray, shape (k,)
    hit_cov_en_m2 : ndarray, shape (k, 2, 2)
    road_enu : ndarray, shape (n, 3)
        The road rule's point; NaN where ``has_road`` is false.
    has_road : ndarray of bool, shape (n,)
    score : ndarray, shape (n,)
        Detector confidence; NaN for none.
    """

    det_id: np.ndarray
    t_s: np.ndarray
    sensor: np.ndarray
    cls: np.ndarray
    origin_enu: np.ndarray
    direction_enu: np.ndarray
    hit_offsets: np.ndarray
    hits_enu: np.ndarray
    hit_sigma_m: np.ndarray
    hit_cov_en_m2: np.ndarray
    road_enu: np.ndarray
    has_road: np.ndarray
    score: np.ndarray

    def __len__(self) -> int:
        return len(self.det_id)

    @classmethod
    def empty(cls) -> FixColumns:
        """No fixes."""
        return cls.from_fixes([], np.zeros(0, np.int64))

    @classmethod
    def from_fixes(cls, fixes: Sequence[Fix], det_ids: np.ndarray) -> FixColumns:
        """Columns of ``fixes``; ``det_ids[f.detection_index]`` is each fix's detection id."""
        n = len(fixes)
        counts = np.array([len(f.hits_enu) for f in fixes], dtype=np.int64)
        offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)

        def stack(get: object, shape: tuple[int, ...]) -> np.ndarray:
            parts = [np.asarray(get(f), dtype=np.float64).reshape(-1, *shape) for f in fixes]  # type: ignore[operator]
            return np.concatenate(parts) if parts else np.zeros((0, *shape))

        cov = stack(
            lambda f: (
                f.hit_cov_en_m2
                if f.hit_cov_en_m2 is not None
                else f.hit_sigma_m[:, None, None] ** 2 * np.eye(2)
            ),
            (2, 2),
        )
        road = np.full((n, 3), np.nan)
        has_road = np.zeros(n, bool)
        for r, f in enumerate(fixes):
            if f.road_hit_enu is not None:
                road[r] = f.road_hit_enu
                has_road[r] = True
        ids = np.asarray(det_ids, dtype=np.int64)
        return cls(
            det_id=np.array([ids[f.detection_index] for f in fixes], dtype=np.int64),
            t_s=np.array([f.t_s for f in fixes], dtype=np.float64),
            sensor=np.array([f.sensor for f in fixes], dtype=object),
            cls=np.array([f.cls for f in fixes], dtype=object),
            origin_enu=stack(lambda f: f.origin_enu, (3,)),
            direction_enu=stack(lambda f: f.direction_enu, (3,)),
            hit_offsets=offsets,
            hits_enu=stack(lambda f: f.hits_enu, (3,)),
            hit_sigma_m=stack(lambda f: f.hit_sigma_m, ()).reshape(-1),
            hit_cov_en_m2=cov,
            road_enu=road,
            has_road=has_road,
            score=np.array([np.nan if f.score is None else f.score for f in fixes], np.float64),
        )

    @classmethod
    def concat(cls, parts: Sequence[FixColumns]) -> FixColumns:
        """One set of columns of several, in the given order."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        shifts = np.cumsum([0] + [int(p.hit_offsets[-1]) for p in parts[:-1]])
        offsets = np.concatenate(
            [[0]] + [p.hit_offsets[1:] + s for p, s in zip(parts, shifts, strict=True)]
        ).astype(np.int64)
        cat = np.concatenate
        return cls(
            det_id=cat([p.det_id for p in parts]),
            t_s=cat([p.t_s for p in parts]),
            sensor=cat([p.sensor for p in parts]),
            cls=cat([p.cls for p in parts]),
            origin_enu=cat([p.origin_enu for p in parts]),
            direction_enu=cat([p.direction_enu for p in parts]),
            hit_offsets=offsets,
            hits_enu=cat([p.hits_enu for p in parts]),
            hit_sigma_m=cat([p.hit_sigma_m for p in parts]),
            hit_cov_en_m2=cat([p.hit_cov_en_m2 for p in parts]),
            road_enu=cat([p.road_enu for p in parts]),
            has_road=cat([p.has_road for p in parts]),
            score=cat([p.score for p in parts]),
        )

    def take(self, rows: np.ndarray) -> FixColumns:
        """The fixes at ``rows`` (int indices), in that order."""
        rows = np.asarray(rows, dtype=np.int64)
        lo, hi = self.hit_offsets[rows], self.hit_offsets[rows + 1]
        counts = hi - lo
        hit_rows = (
            np.concatenate([np.arange(a, b) for a, b in zip(lo.tolist(), hi.tolist(), strict=True)])
            if len(rows)
            else np.zeros(0, np.int64)
        ).astype(np.int64)
        return FixColumns(
            det_id=self.det_id[rows],
            t_s=self.t_s[rows],
            sensor=self.sensor[rows],
            cls=self.cls[rows],
            origin_enu=self.origin_enu[rows],
            direction_enu=self.direction_enu[rows],
            hit_offsets=np.concatenate(([0], np.cumsum(counts))).astype(np.int64),
            hits_enu=self.hits_enu[hit_rows],
            hit_sigma_m=self.hit_sigma_m[hit_rows],
            hit_cov_en_m2=self.hit_cov_en_m2[hit_rows],
            road_enu=self.road_enu[rows],
            has_road=self.has_road[rows],
            score=self.score[rows],
        )

    def sorted(self) -> FixColumns:
        """The fixes in detection-id order (the archive's canonical time order)."""
        return self.take(np.argsort(self.det_id, kind="stable"))

    def to_fixes(self) -> list[Fix]:
        """The :class:`Fix` values; ``detection_index`` is the detection id."""
        if not len(self):
            return []
        return Fix.from_arrays(
            self.t_s.tolist(),
            self.sensor.tolist(),
            self.cls.tolist(),
            self.det_id.tolist(),
            self.origin_enu,
            self.direction_enu,
            self.hit_offsets,
            self.hits_enu,
            self.hit_sigma_m,
            road_hit_enu=np.nan_to_num(self.road_enu),
            has_road=self.has_road,
            score=[None if s != s else s for s in self.score.tolist()],
            hit_cov_en_m2=self.hit_cov_en_m2,
        )

    def to_arrow(self) -> pa.Table:
        """A table, one row per fix: ray, every hit (list columns), road point, score."""
        off = pa.array(self.hit_offsets.astype(np.int32))

        def listed(values: np.ndarray) -> pa.Array:
            return pa.ListArray.from_arrays(off, pa.array(values))

        cov = self.hit_cov_en_m2.reshape(-1, 4)
        road = np.where(self.has_road[:, None], self.road_enu, np.nan)
        cols = {
            "det_id": self.det_id,
            "t_s": self.t_s,
            "sensor": pa.array(self.sensor.tolist(), pa.string()),
            "cls": pa.array(self.cls.tolist(), pa.string()),
            **{f"origin_{a}": self.origin_enu[:, k] for k, a in enumerate("enu")},
            **{f"dir_{a}": self.direction_enu[:, k] for k, a in enumerate("enu")},
            **{f"hit_{a}": listed(self.hits_enu[:, k]) for k, a in enumerate("enu")},
            "hit_sigma_m": listed(self.hit_sigma_m),
            **{f"hit_cov_{n}": listed(cov[:, k]) for k, n in enumerate(("ee", "en", "ne", "nn"))},
            **{f"road_{a}": pa.array(road[:, k], from_pandas=True) for k, a in enumerate("enu")},
            "score": pa.array(self.score, from_pandas=True),
        }
        return pa.table(cols)
