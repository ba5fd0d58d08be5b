"""Sensor poses that change over time: telemetry samples, series, and the pose at a moment.

A PTZ head reports its pan, tilt and zoom (and, on a moving platform, its position and
attitude) as telemetry, each sample stamped by the telemetry's own clock. A detection is
geolocated with the pose *of its own moment*: :meth:`PoseSeries.at` interpolates the
series at the detection times, and refuses (``ok = False``) where no sample is close
enough, rather than hand back a stale pose.

Frames and angles
    ``pan_deg``, ``tilt_deg``, ``roll_deg`` are the head's joint angles in the sense of
    :meth:`~demtrack.core.camera.pantilt.PanTiltHead.camera_at`: the camera's azimuth on
    the mount is ``mount_yaw_deg + pan_deg`` (clockwise), its elevation ``tilt_deg``
    (+ up), ``roll_deg`` its bank about the optical axis (+ lowers the image's right
    side). On a fixed levelled mount those are angles of the site frame. On a moving
    platform they are angles of the **platform body frame** (x right/starboard, y
    forward/nose, z up), whose attitude ``platform_ypr_deg = (yaw, pitch, roll)`` is yaw
    clockwise from true north, pitch + nose up, roll + right wing down, applied in that
    order (intrinsic z-x'-y''): ``R_world_body = Rz(-yaw) Rx(pitch) Ry(roll)`` with
    right-handed ``R*`` about the site's E, N, U axes. The camera is then
    ``R_world_cam = R_world_body @ R_body_cam(mount_yaw + pan, tilt, roll)``, and its
    optical centre ``position_enu`` (site frame, m) when given, else the head's surveyed one.

Time and latency
    ``t_s`` is UNIX seconds UTC. ``latency_s`` is how late the telemetry's stamps are
    relative to the video frames: the telemetry time of video time ``t`` is
    ``t' = t + latency_s``. Worked example: the head reports each pose 80 ms after the
    moment it held it (its stamps are late, ``latency_s = +0.08``); a frame taken at
    ``t = 100.000 s`` is geolocated with the series at ``t' = 100.080 s``, the sample
    stamped for that frame's moment. A negative latency means telemetry stamps early.

Interpolation (:meth:`PoseSeries.at`)
    Between the two samples that bracket ``t'``: pan, tilt, roll and hfov linearly (pan
    the short way across +-180: ``pan0 + a * wrap(pan1 - pan0)``, not wrapped after, so a
    head that reports unwrapped pans gets its own numbers back), position linearly, and
    the **platform attitude by slerp** of unit quaternions. The head's joint angles are
    interpolated as joints (the head moves its axes at rates, so the joint path is the
    physical one; slerping the whole camera attitude would cut the corner near the
    zenith), and the platform's attitude, which has no joints, as a rotation (its Euler
    angles wrap and are singular at pitch +-90). Beyond either end of the series, within
    the gap, the end sample is held.

The gap rule
    ``ok[i]`` is true iff some sample lies within ``max_gap_s`` of ``t'`` (both ends
    included, 1 us tolerance, as every time boundary in demtrack): inside a long hole in
    the telemetry, before the first sample or after the last by more than the gap, the
    pose is unknown and every value is NaN. Default gap 0.2 s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import PoseError
from .attitude import (
    quat_from_rotation,
    rotation_from_quat,
    rotations_from_azimuth_tilt_roll,
    rotations_from_ypr,
    slerp,
    ypr_from_rotation,
)
from .pantilt import PanTiltHead
from .pinhole import Camera
from .zoom_lens import ZoomTable, intrinsics_for_hfov

__all__ = [
    "DEFAULT_MAX_GAP_S",
    "TIME_TOLERANCE_S",
    "PoseBatch",
    "PoseSample",
    "PoseSeries",
    "camera_at",
]

#: Default largest distance (s) from a query to its nearest telemetry sample.
DEFAULT_MAX_GAP_S = 0.2
#: Times within this of a boundary count as on it (camera clocks are microseconds).
TIME_TOLERANCE_S = 1e-6


def _finite(value: Any, name: str) -> float:
    if isinstance(value, bool):
        raise PoseError(f"pose {name} must be a number, got {value!r}")
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise PoseError(f"pose {name} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise PoseError(f"pose {name} must be finite, got {value!r}")
    return out


def _triple(value: Any, name: str) -> tuple[float, float, float] | None:
    if value is None:
        return None
    try:
        items = list(value)
    except TypeError:
        raise PoseError(f"pose {name} must be 3 numbers, got {value!r}") from None
    if len(items) != 3:
        raise PoseError(f"pose {name} must be 3 numbers, got {len(items)}")
    a, b, c = (_finite(x, name) for x in items)
    return a, b, c


@dataclass(frozen=True)
class PoseSample:
    """One telemetry sample of a sensor's pose (see the module notes for frames).

    Parameters
    ----------
    t_s : float
        UNIX seconds UTC, the telemetry's own stamp.
    pan_deg, tilt_deg : float
        Head pan (clockwise) and tilt (elevation, + up; within [-90, 90]).
    hfov_deg : float or None
        Zoom as horizontal field of view (degrees, (0, 180)); None: the calibrated lens.
    roll_deg : float
        Camera bank about the optical axis (+ lowers the image's right side).
    position_enu : (float, float, float) or None
        Optical centre of a moving platform (site frame, m); None: the head's surveyed one.
    platform_ypr_deg : (float, float, float) or None
        Platform yaw (clockwise from true north), pitch (+ nose up), roll (+ right wing
        down), degrees; None: a levelled fixed mount.

    Raises
    ------
    PoseError
        On a value that is not a finite number, a tilt outside [-90, 90] or an hfov
        outside (0, 180).
    """

    t_s: float
    pan_deg: float
    tilt_deg: float
    hfov_deg: float | None = None
    roll_deg: float = 0.0
    position_enu: tuple[float, float, float] | None = None
    platform_ypr_deg: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        for name in ("t_s", "pan_deg", "tilt_deg", "roll_deg"):
            object.__setattr__(self, name, _finite(getattr(self, name), name))
        if not -90.0 <= self.tilt_deg <= 90.0:
            raise PoseError(f"pose tilt_deg must be within [-90, 90], got {self.tilt_deg}")
        if self.hfov_deg is not None:
            h = _finite(self.hfov_deg, "hfov_deg")
            if not 0.0 < h < 180.0:
                raise PoseError(f"pose hfov_deg must be in (0, 180) degrees, got {h}")
            object.__setattr__(self, "hfov_deg", h)
        object.__setattr__(self, "position_enu", _triple(self.position_enu, "position_enu"))
        object.__setattr__(
            self, "platform_ypr_deg", _triple(self.platform_ypr_deg, "platform_ypr_deg")
        )


def camera_at(head: PanTiltHead, pose: PoseSample, zoom: ZoomTable | None = None) -> Camera:
    """The camera of ``head`` at ``pose`` (module notes: frames; ``zoom``: the lens table).

    With no hfov, no roll, no position and no platform this is exactly
    ``head.camera_at(pose.pan_deg, pose.tilt_deg)``.

    Raises
    ------
    PoseError
        For an hfov outside ``zoom``'s table.
    CameraError
        For a zoom at which the lens model has no inverse over the image (a zoom much
        wider than the calibrated one, on a strongly distorted lens).
    """
    intr = head.intrinsics
    if pose.hfov_deg is not None:
        intr = intrinsics_for_hfov(head.intrinsics, pose.hfov_deg, zoom)
    position = head.position_enu if pose.position_enu is None else np.array(pose.position_enu)
    az = head.mount_yaw_deg + pose.pan_deg
    if pose.platform_ypr_deg is None:
        return Camera.from_azimuth_tilt_roll(intr, position, az, pose.tilt_deg, pose.roll_deg)
    r_body_cam = rotations_from_azimuth_tilt_roll(
        np.array([az]), np.array([pose.tilt_deg]), np.array([pose.roll_deg])
    )[0]
    r_world_body = rotations_from_ypr(np.array([pose.platform_ypr_deg]))[0]
    return Camera(intr, position, _orthonormal(r_world_body @ r_body_cam))


def _orthonormal(r: np.ndarray) -> np.ndarray:
    """The nearest rotation to ``r`` (round-off only), so :class:`Camera` accepts it."""
    u, _, vt = np.linalg.svd(r)
    return u @ vt


@dataclass(frozen=True, eq=False)
class PoseBatch:
    """Poses interpolated at ``n`` query times (:meth:`PoseSeries.at`).

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        The query (video) times, UNIX s.
    ok : ndarray of bool, shape (n,)
        A sample lies close enough (the gap rule); where False every value is NaN.
    pan_deg, tilt_deg, roll_deg : ndarray, shape (n,)
        Head joint angles (degrees).
    hfov_deg : ndarray, shape (n,)
        Zoom; NaN where the series has none (the calibrated lens).
    position_enu : ndarray, shape (n, 3)
        Optical centre (site frame, m); NaN where the series has no positions.
    platform_R_world_body : ndarray, shape (n, 3, 3)
        Platform attitude (identity where the series has none, NaN where not ok).
    R_world_cam : ndarray, shape (n, 3, 3) or None
        Camera rotations when ``at`` was given a head (NaN where not ok), else None;
        :meth:`camera_rotations` computes them for any head.
    has_platform : bool
        The series carries platform attitudes.
    """

    t_s: np.ndarray
    ok: np.ndarray
    pan_deg: np.ndarray
    tilt_deg: np.ndarray
    roll_deg: np.ndarray
    hfov_deg: np.ndarray
    position_enu: np.ndarray
    platform_R_world_body: np.ndarray  # noqa: N815 - frame names follow the convention
    R_world_cam: np.ndarray | None = None  # noqa: N815
    has_platform: bool = False

    def __len__(self) -> int:
        return int(len(self.t_s))

    def camera_rotations(self, head: PanTiltHead) -> np.ndarray:
        """``R_world_cam`` of ``head`` at each pose, shape (n, 3, 3); NaN where not ok."""
        platform = self.platform_R_world_body if self.has_platform else None
        return _camera_rotations(head, self.pan_deg, self.tilt_deg, self.roll_deg, platform)

    def positions(self, head: PanTiltHead) -> np.ndarray:
        """Optical centres (site frame, m), shape (n, 3): the head's where none is given."""
        out = self.position_enu.copy()
        none = ~np.isfinite(out).all(axis=1)
        out[none] = head.position_enu
        out[~self.ok] = np.nan
        return out

    def sample(self, i: int) -> PoseSample | None:
        """The pose at query ``i`` as a :class:`PoseSample` (None where not ok)."""
        if not self.ok[i]:
            return None
        hfov = float(self.hfov_deg[i])
        pos = self.position_enu[i]
        ypr = None
        if self.has_platform:
            ypr = tuple(float(x) for x in ypr_from_rotation(self.platform_R_world_body[i])[0])
        return PoseSample(
            float(self.t_s[i]),
            float(self.pan_deg[i]),
            float(self.tilt_deg[i]),
            hfov if math.isfinite(hfov) else None,
            float(self.roll_deg[i]),
            tuple(float(x) for x in pos) if np.isfinite(pos).all() else None,  # type: ignore[arg-type]
            ypr,  # type: ignore[arg-type]
        )


def _column(values: Any, n: int, name: str, width: int = 0) -> np.ndarray:
    shape = (n,) if not width else (n, width)
    arr = np.array(values, dtype=np.float64)
    if arr.shape != shape:
        raise PoseError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


class PoseSeries:
    """An immutable time series of one sensor's poses, times strictly increasing.

    Build it with :meth:`from_samples` or :meth:`from_arrays`. Optional parts (hfov,
    position, platform attitude) are all-or-nothing over a series: a series whose
    samples disagree about having one is refused.
    """

    __slots__ = ("_hfov", "_pan", "_pos", "_quat", "_roll", "_t", "_tilt", "_ypr")

    def __init__(
        self,
        t_s: np.ndarray,
        pan_deg: np.ndarray,
        tilt_deg: np.ndarray,
        hfov_deg: np.ndarray | None,
        roll_deg: np.ndarray,
        position_enu: np.ndarray | None,
        platform_ypr_deg: np.ndarray | None,
    ) -> None:
        # Private: the classmethods validate.
        self._t, self._pan, self._tilt, self._roll = t_s, pan_deg, tilt_deg, roll_deg
        self._hfov, self._pos, self._ypr = hfov_deg, position_enu, platform_ypr_deg
        self._quat = (
            None
            if platform_ypr_deg is None
            else quat_from_rotation(rotations_from_ypr(platform_ypr_deg))
        )
        for a in self._parts() + (self._quat,):
            if a is not None:
                a.setflags(write=False)

    def _parts(self) -> tuple[Any, ...]:
        return (self._t, self._pan, self._tilt, self._hfov, self._roll, self._pos, self._ypr)

    @classmethod
    def from_samples(cls, samples: Sequence[PoseSample]) -> PoseSeries:
        """A series from samples in time order (strictly increasing; may be empty).

        Raises
        ------
        PoseError
            On times not strictly increasing, or optional parts given by some samples only.
        """
        samples = list(samples)
        if not all(isinstance(s, PoseSample) for s in samples):
            raise PoseError("a pose series is built from PoseSample values")
        for name in ("hfov_deg", "position_enu", "platform_ypr_deg"):
            given = {getattr(s, name) is not None for s in samples}
            if len(given) > 1:
                raise PoseError(f"pose series: {name} is given by some samples but not all")
        first = samples[0] if samples else None

        def column(name: str) -> list[Any] | None:
            return (
                None
                if first is None or getattr(first, name) is None
                else [getattr(s, name) for s in samples]
            )

        return cls.from_arrays(
            [s.t_s for s in samples],
            [s.pan_deg for s in samples],
            [s.tilt_deg for s in samples],
            column("hfov_deg"),
            [s.roll_deg for s in samples],
            column("position_enu"),
            column("platform_ypr_deg"),
        )

    @classmethod
    def from_arrays(
        cls,
        t_s: ArrayLike,
        pan_deg: ArrayLike,
        tilt_deg: ArrayLike,
        hfov_deg: ArrayLike | None = None,
        roll_deg: ArrayLike | None = None,
        position_enu: ArrayLike | None = None,
        platform_ypr_deg: ArrayLike | None = None,
    ) -> PoseSeries:
        """A series from columns: shapes (n,), position (n, 3), platform yaw-pitch-roll (n, 3).

        Raises
        ------
        PoseError
            On mismatched shapes, non-finite values, tilts outside [-90, 90], hfovs
            outside (0, 180), or times not strictly increasing.
        """
        t = np.array(t_s, dtype=np.float64).reshape(-1)
        n = len(t)
        pan = _column(pan_deg, n, "pan_deg")
        tilt = _column(tilt_deg, n, "tilt_deg")
        roll = np.zeros(n) if roll_deg is None else _column(roll_deg, n, "roll_deg")
        hfov = None if hfov_deg is None else _column(hfov_deg, n, "hfov_deg")
        pos = None if position_enu is None else _column(position_enu, n, "position_enu", 3)
        ypr = None if platform_ypr_deg is None else _column(platform_ypr_deg, n, "ypr", 3)
        for name, a in (
            ("t_s", t), ("pan_deg", pan), ("tilt_deg", tilt), ("roll_deg", roll),
            ("hfov_deg", hfov), ("position_enu", pos), ("platform_ypr_deg", ypr),
        ):  # fmt: skip
            if a is not None and not np.isfinite(a).all():
                i = int(np.flatnonzero(~np.isfinite(a).reshape(n, -1).all(axis=1))[0])
                raise PoseError(f"pose series: {name} of sample {i} is not finite")
        bad = np.flatnonzero(np.abs(tilt) > 90.0)
        if bad.size:
            raise PoseError(f"pose series: tilt_deg {tilt[bad[0]]} outside [-90, 90]")
        if hfov is not None and not ((hfov > 0.0) & (hfov < 180.0)).all():
            h = hfov[~((hfov > 0.0) & (hfov < 180.0))][0]
            raise PoseError(f"pose series: hfov_deg {h} outside (0, 180)")
        steps = np.flatnonzero(np.diff(t) <= 0.0)
        if steps.size:
            i = int(steps[0])
            raise PoseError(
                f"pose series times must increase strictly: sample {i + 1} at {t[i + 1]!r} s "
                f"is not after {t[i]!r} s"
            )
        return cls(t, pan, tilt, hfov, roll, pos, ypr)

    def __len__(self) -> int:
        return int(len(self._t))

    def __repr__(self) -> str:
        if not len(self):
            return "PoseSeries(empty)"
        return f"PoseSeries({len(self)} samples, {self._t[0]!r} .. {self._t[-1]!r} s)"

    @property
    def t_s(self) -> np.ndarray:
        """Sample times, UNIX s, shape (n,) (read-only)."""
        return self._t

    @property
    def has_zoom(self) -> bool:
        """The samples carry hfov."""
        return self._hfov is not None

    @property
    def has_position(self) -> bool:
        """The samples carry optical-centre positions (a moving platform)."""
        return self._pos is not None

    @property
    def has_platform(self) -> bool:
        """The samples carry platform attitudes."""
        return self._quat is not None

    def samples(self) -> list[PoseSample]:
        """The samples, in time order."""
        ypr = self._ypr
        out = []
        for i in range(len(self)):
            out.append(
                PoseSample(
                    float(self._t[i]),
                    float(self._pan[i]),
                    float(self._tilt[i]),
                    None if self._hfov is None else float(self._hfov[i]),
                    float(self._roll[i]),
                    None if self._pos is None else tuple(self._pos[i].tolist()),  # type: ignore[arg-type]
                    None if ypr is None else tuple(ypr[i].tolist()),  # type: ignore[arg-type]
                )
            )
        return out

    def extended(self, samples: Sequence[PoseSample]) -> PoseSeries:
        """A copy with newer ``samples`` appended (each after the last one).

        Raises
        ------
        PoseError
            When a sample is not after the series' last, or its optional parts differ.
        """
        if not len(self):
            return PoseSeries.from_samples(samples)
        if not samples:
            return self
        new = PoseSeries.from_samples(samples)
        for name in ("has_zoom", "has_position", "has_platform"):
            if getattr(new, name) != getattr(self, name):
                raise PoseError(f"pose series: new samples differ in {name[4:]} from the series")
        if new._t[0] <= self._t[-1]:
            raise PoseError(
                f"pose series: a new sample at {new._t[0]!r} s is not after the last one "
                f"({self._t[-1]!r} s)"
            )
        joined: list[Any] = [
            None if a is None else np.concatenate([a, b])
            for a, b in zip(self._parts(), new._parts(), strict=True)
        ]
        return PoseSeries(*joined)

    def since(self, t_s: float) -> PoseSeries:
        """Drop samples older than ``t_s``, keeping the last one at or before it.

        Queries at ``t_s`` or later answer as before (their bracket is kept).
        """
        k = max(int(np.searchsorted(self._t, float(t_s), side="right")) - 1, 0)
        if k == 0:
            return self
        parts: list[Any] = [None if a is None else a[k:].copy() for a in self._parts()]
        return PoseSeries(*parts)

    def at(
        self,
        t_s: ArrayLike,
        *,
        max_gap_s: float = DEFAULT_MAX_GAP_S,
        latency_s: float = 0.0,
        head: PanTiltHead | None = None,
    ) -> PoseBatch:
        """The poses at video times ``t_s`` (rules in the module notes).

        Parameters
        ----------
        t_s : array_like, shape (n,)
            Video (frame) times, UNIX s.
        max_gap_s : float
            Largest distance (s, >= 0) from ``t + latency_s`` to the nearest sample.
        latency_s : float
            How late telemetry stamps are relative to frames (s); ``t' = t + latency_s``.
        head : PanTiltHead, optional
            Fills :attr:`PoseBatch.R_world_cam` with this head's camera rotations.

        Returns
        -------
        PoseBatch
        """
        gap = _finite(max_gap_s, "max_gap_s")
        lat = _finite(latency_s, "latency_s")
        if gap < 0.0:
            raise PoseError(f"max_gap_s must be >= 0 s, got {gap}")
        q = np.array(t_s, dtype=np.float64).reshape(-1)
        n, m = len(q), len(self)
        tq = q + lat
        if m == 0:
            ok = np.zeros(n, bool)
            k0 = k1 = np.zeros(n, np.int64)
            a = np.zeros(n)
        else:
            k = np.searchsorted(self._t, tq, side="right") - 1
            k0 = np.clip(k, 0, m - 1)
            k1 = np.clip(k + 1, 0, m - 1)
            t = self._t
            near = np.minimum(np.abs(tq - t[k0]), np.abs(t[k1] - tq))
            ok = np.isfinite(tq) & (near <= gap + TIME_TOLERANCE_S)
            span = t[k1] - t[k0]
            inside = k1 != k0
            a = np.zeros(n)
            a[inside] = (tq[inside] - t[k0[inside]]) / span[inside]
            a = np.clip(a, 0.0, 1.0)
        nan = np.full(n, np.nan)
        if m == 0:
            pan = tilt = roll = hfov = nan.copy()
        else:
            p0, p1 = self._pan[k0], self._pan[k1]
            dp = np.mod(p1 - p0 + 180.0, 360.0) - 180.0
            pan = np.where(a == 0.0, p0, p0 + a * dp)
            tilt = _lerp(self._tilt, k0, k1, a)
            roll = _lerp(self._roll, k0, k1, a)
            hfov = nan.copy() if self._hfov is None else _lerp(self._hfov, k0, k1, a)
        pos = np.full((n, 3), np.nan)
        if self._pos is not None and m:
            p0, p1 = self._pos[k0], self._pos[k1]
            pos = np.where((a == 0.0)[:, None], p0, p0 + a[:, None] * (p1 - p0))
        rot = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        if self._quat is not None and m:
            rot = rotation_from_quat(slerp(self._quat[k0], self._quat[k1], a))
        for arr in (pan, tilt, roll, hfov):
            arr[~ok] = np.nan
        pos[~ok] = np.nan
        rot[~ok] = np.nan
        has_platform = self._quat is not None
        r_world_cam = None
        if head is not None:
            r_world_cam = _camera_rotations(head, pan, tilt, roll, rot if has_platform else None)
        return PoseBatch(q, ok, pan, tilt, roll, hfov, pos, rot, r_world_cam, has_platform)


def _camera_rotations(
    head: PanTiltHead,
    pan_deg: np.ndarray,
    tilt_deg: np.ndarray,
    roll_deg: np.ndarray,
    platform: np.ndarray | None,
) -> np.ndarray:
    """``R_world_cam`` (n, 3, 3) of head joint angles, on a platform ``R_world_body`` if any."""
    r = rotations_from_azimuth_tilt_roll(head.mount_yaw_deg + pan_deg, tilt_deg, roll_deg)
    return r if platform is None else platform @ r


def _lerp(v: np.ndarray, k0: np.ndarray, k1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``v[k0] + a (v[k1] - v[k0])``, exactly ``v[k0]`` where ``a`` is 0 (at a sample)."""
    v0, v1 = v[k0], v[k1]
    return np.where(a == 0.0, v0, v0 + a * (v1 - v0))
