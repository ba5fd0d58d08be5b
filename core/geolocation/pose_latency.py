"""Estimating a sensor's pose latency from data: the latency that makes tracks smoothest.

A PTZ head's telemetry stamps and its video frames come from different clocks, and the
telemetry is usually late by a fixed amount (``pose_latency_s``: the pose of a frame at
``t`` is the series at ``t + pose_latency_s``; :mod:`demtrack.core.camera.pose_series`).
With the wrong latency each fix is computed with the pose of another moment: the error
is the head's angular velocity times the latency error, so wherever the head's motion is
not uniform (it corrects, wobbles, accelerates as it follows) the geolocated ground
track of a smoothly moving target jitters. The right latency minimises that jitter.

:func:`estimate_pose_latency` geolocates one moving target's detections at each
candidate latency (:func:`~demtrack.core.geolocation.fix_builder.build_fixes`, foot
offsets off, the nearest terrain hit) and scores the ground track by its **robust
jitter**: the trimmed mean (largest ``trim`` share dropped: a wrong association, a
box that jumped) of the squared second differences of position over time
(accelerations, m^2/s^4, with the uneven-step formula), taken between fixes about
``lag_s`` apart (default 0.4 s). The lag matters: differencing consecutive frames twice
amplifies pixel noise by ``1 / dt^2`` (0.3 m of range noise at 25 Hz is 400 m/s^2), while
the jitter a latency error makes follows the head's corrections, a few per second. It
scans the search range on a coarse grid, then refines the best bracket by golden-section
search to ``tol_s``.
Detections whose time plus any candidate latency falls outside the series are left out,
so every candidate scores the same detections.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..errors import PoseError
from ..tracking.types import Detection
from .fix_builder import build_fixes

if TYPE_CHECKING:  # types only: the site (a layer above) and the series are passed in
    from ..camera.pose_series import PoseSeries
    from ..site.folder import Site

__all__ = ["LatencyEstimate", "estimate_pose_latency", "track_jitter"]

_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True, eq=False)
class LatencyEstimate:
    """The latency that minimises track jitter, and the curve it was read from.

    Attributes
    ----------
    latency_s : float
        The estimate (s; telemetry stamps this late relative to the frames).
    jitter : float
        The robust jitter there (m^2/s^4).
    curve_latency_s, curve_jitter : ndarray, shape (k,)
        Every candidate scored (coarse grid and refinement), sorted by latency.
    n_detections : int
        Detections scored (those inside the series at every candidate).
    """

    latency_s: float
    jitter: float
    curve_latency_s: np.ndarray
    curve_jitter: np.ndarray
    n_detections: int

    def summary(self) -> str:
        """One line for the operator."""
        return (
            f"pose latency {self.latency_s * 1000:+.1f} ms (track jitter "
            f"{self.jitter:.3g} m^2/s^4 over {self.n_detections} detections)"
        )


def track_jitter(t_s: np.ndarray, p_en: np.ndarray, trim: float = 0.1, stride: int = 1) -> float:
    """Robust jitter of a ground track: trimmed mean squared acceleration (m^2/s^4).

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Strictly increasing times.
    p_en : ndarray, shape (n, 2)
        Horizontal positions (m).
    trim : float
        Share of the largest squared accelerations left out, in [0, 1).
    stride : int
        Second differences of points ``k - stride, k, k + stride``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    p = np.asarray(p_en, dtype=np.float64)
    m = int(stride)
    if len(t) < 2 * m + 1:
        return math.nan
    dt0 = t[m:-m] - t[: -2 * m]
    dt1 = t[2 * m :] - t[m:-m]
    vel0 = (p[m:-m] - p[: -2 * m]) / dt0[:, None]
    vel1 = (p[2 * m :] - p[m:-m]) / dt1[:, None]
    acc = (vel1 - vel0) / (0.5 * (dt0 + dt1))[:, None]
    sq = np.sort(np.sum(acc * acc, axis=1))
    keep = max(1, int(math.ceil(len(sq) * (1.0 - trim))))
    return float(np.mean(sq[:keep]))


def estimate_pose_latency(
    site: Site,
    detections: Sequence[Detection],
    series: PoseSeries,
    sensor_id: str,
    *,
    search_s: tuple[float, float] = (-0.5, 0.5),
    coarse_step_s: float = 0.02,
    tol_s: float = 1e-3,
    trim: float = 0.1,
    lag_s: float = 0.4,
) -> LatencyEstimate:
    """Estimate ``sensor_id``'s pose latency from one moving target's detections.

    Parameters
    ----------
    site : Site
        The site (DEM, the sensor's head and lens; its ``max_pose_gap_s`` is used).
    detections : sequence of Detection
        One target seen by the sensor (others' detections are ignored); one per frame.
    series : PoseSeries
        The sensor's pose telemetry.
    sensor_id : str
    search_s : (float, float)
        Latencies searched (s).
    coarse_step_s : float
        Step of the first scan (s).
    tol_s : float
        Width of the final bracket (s).
    trim : float
        Share of the largest accelerations left out of the jitter.
    lag_s : float
        Time between the fixes of each second difference (s; rounded to whole frames).

    Raises
    ------
    PoseError
        With fewer than 5 usable detections, a bad search range, or a bracket where no
        latency geolocates enough of them.
    """
    lo, hi = (float(x) for x in search_s)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise PoseError(f"search_s must be an increasing pair of seconds, got {search_s}")
    if not (coarse_step_s > 0 and tol_s > 0 and 0 <= trim < 1):
        raise PoseError("coarse_step_s and tol_s must be > 0 and trim in [0, 1)")
    sensor = site.sensor(sensor_id)
    if len(series) < 2:
        raise PoseError("a latency estimate needs a pose series of at least 2 samples")
    t_first, t_last = float(series.t_s[0]), float(series.t_s[-1])
    seen: set[float] = set()
    use: list[Detection] = []
    for det in sorted((d for d in detections if d.sensor == sensor_id), key=lambda d: d.t_s):
        if det.t_s in seen or det.t_s + lo < t_first or det.t_s + hi > t_last:
            continue
        seen.add(det.t_s)
        use.append(det)
    if len(use) < 5:
        raise PoseError(
            f"a latency estimate needs at least 5 detections of {sensor_id} inside the pose "
            f"series at every candidate latency; {len(use)} are"
        )
    no_offset = {"vehicle": 0.0, "human": 0.0}
    frame_s = float(np.median(np.diff([d.t_s for d in use])))
    stride = max(1, int(round(float(lag_s) / frame_s)))
    scored: dict[float, float] = {}

    def jitter(latency: float) -> float:
        if latency in scored:
            return scored[latency]
        trial = replace(
            site, sensors={**site.sensors, sensor_id: replace(sensor, pose_latency_s=latency)}
        )
        fixes, _ = build_fixes(trial, use, poses={sensor_id: series}, foot_offset_m=no_offset)
        if len(fixes) < max(5, 2 * stride + 1):
            value = math.inf
        else:
            t = np.array([f.t_s for f in fixes])
            p = np.array([f.hits_enu[0, :2] for f in fixes], dtype=np.float64)
            value = track_jitter(t, p, trim, stride)
        scored[latency] = value
        return value

    grid = np.linspace(lo, hi, max(3, int(round((hi - lo) / coarse_step_s)) + 1))
    values = np.array([jitter(float(x)) for x in grid])
    if not np.isfinite(values).any():
        raise PoseError(f"no latency in {lo:g} .. {hi:g} s geolocates 5 of the detections")
    k = int(np.nanargmin(values))
    a, b = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, len(grid) - 1)])
    c, d = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
    while b - a > tol_s:
        if jitter(c) <= jitter(d):
            b, d = d, c
            c = b - _GOLDEN * (b - a)
        else:
            a, c = c, d
            d = a + _GOLDEN * (b - a)
    best = min(scored, key=lambda x: scored[x])
    xs = np.array(sorted(scored))
    return LatencyEstimate(best, scored[best], xs, np.array([scored[x] for x in xs]), len(use))
