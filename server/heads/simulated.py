"""A simulated pan-tilt-zoom head: :mod:`demtrack.core.camera.head_motion` on a clock."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from demtrack.core.camera.head_motion import HeadCommand, HeadState, SlewLimits, step

from .adapter import HeadStatus

__all__ = ["SimulatedHead"]


class SimulatedHead:
    """A head that moves under its limits as real time (or an injected clock) passes.

    Parameters
    ----------
    limits : SlewLimits
        Rate, acceleration and range limits.
    pan_deg, tilt_deg, hfov_deg : float
        Where it points at start (degrees).
    clock : callable, optional
        UNIX seconds now; ``time.time`` by default (tests pass their own).

    Notes
    -----
    The state is advanced lazily, on each call, from the last call's time under the
    command in force: :func:`~demtrack.core.camera.head_motion.step` integrates the
    profile exactly, so how often it is read does not change where the head goes.
    Thread-safe.
    """

    def __init__(
        self,
        limits: SlewLimits,
        pan_deg: float = 0.0,
        tilt_deg: float = 0.0,
        hfov_deg: float | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.limits = limits
        self._clock = clock
        hfov = limits.hfov_max_deg if hfov_deg is None else hfov_deg
        self._state = HeadState(clock(), pan_deg, tilt_deg, hfov)
        self._command: HeadCommand | None = None
        self._lock = threading.Lock()

    def _advance(self) -> HeadState:
        now = self._clock()
        dt = max(0.0, now - self._state.t_s)
        self._state = step(self._state, self._command, dt, self.limits)
        return self._state

    def state(self) -> HeadState:
        """The kinematic state now (with rates)."""
        with self._lock:
            return self._advance()

    def status(self) -> HeadStatus:
        """Where the head points now."""
        with self._lock:
            s = self._advance()
            moving = self._moving(s)
        return HeadStatus(s.t_s, s.pan_deg, s.tilt_deg, s.hfov_deg, moving)

    def _moving(self, s: HeadState) -> bool:
        """Whether the command in force still moves any axis (a millisecond on)."""
        if s.pan_rate_deg_s != 0.0 or s.tilt_rate_deg_s != 0.0:
            return True
        nxt = step(s, self._command, 1e-3, self.limits)
        return (nxt.pan_deg, nxt.tilt_deg, nxt.hfov_deg) != (s.pan_deg, s.tilt_deg, s.hfov_deg)

    def absolute_move(self, pan_deg: float, tilt_deg: float, hfov_deg: float | None) -> None:
        """Move to a pan and tilt (degrees) and, unless ``None``, a field of view."""
        with self._lock:
            self._advance()
            self._command = HeadCommand(pan_deg=pan_deg, tilt_deg=tilt_deg, hfov_deg=hfov_deg)

    def continuous_move(
        self, pan_rate_deg_s: float, tilt_rate_deg_s: float, zoom_rate_deg_s: float
    ) -> None:
        """Turn at these rates (degrees per second, clamped to the limits)."""
        with self._lock:
            self._advance()
            self._command = HeadCommand(
                pan_rate_deg_s=pan_rate_deg_s,
                tilt_rate_deg_s=tilt_rate_deg_s,
                zoom_rate_deg_s=zoom_rate_deg_s,
            )

    def stop(self) -> None:
        """Brake every axis to a stop."""
        with self._lock:
            self._advance()
            self._command = None
