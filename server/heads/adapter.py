"""The protocol between the server and a pan-tilt-zoom head, and its status value.

Every adapter is synchronous: the controller calls it from its own thread (ONVIF is
blocking HTTP with a timeout on every call), never from the event loop.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from demtrack.core.errors import DemtrackError

__all__ = ["HeadAdapter", "HeadAdapterError", "HeadStatus"]


class HeadAdapterError(DemtrackError, ConnectionError):
    """A head that did not answer, answered a SOAP fault, or answered nonsense."""


@dataclass(frozen=True)
class HeadStatus:
    """What a head reports.

    Parameters
    ----------
    t_s : float
        UNIX time (s, UTC) the position belongs to (the head's clock when it says).
    pan_deg, tilt_deg : float
        Pan (degrees clockwise from the mount's zero, in (-180, 180]) and tilt (degrees,
        positive up).
    hfov_deg : float
        Horizontal field of view (degrees).
    moving : bool
        Whether any axis is moving.
    """

    t_s: float
    pan_deg: float
    tilt_deg: float
    hfov_deg: float
    moving: bool

    def to_dict(self) -> dict[str, float | bool]:
        """``{t_s, pan_deg, tilt_deg, hfov_deg, moving}``."""
        return {
            "t_s": self.t_s,
            "pan_deg": self.pan_deg,
            "tilt_deg": self.tilt_deg,
            "hfov_deg": self.hfov_deg,
            "moving": self.moving,
        }


@runtime_checkable
class HeadAdapter(Protocol):
    """A head the server can read and move. Every call may raise :class:`HeadAdapterError`."""

    def status(self) -> HeadStatus:
        """Where the head points now."""
        ...

    def absolute_move(self, pan_deg: float, tilt_deg: float, hfov_deg: float | None) -> None:
        """Move to a pan and tilt (degrees) and, unless ``None``, a field of view."""
        ...

    def continuous_move(
        self, pan_rate_deg_s: float, tilt_rate_deg_s: float, zoom_rate_deg_s: float
    ) -> None:
        """Turn at these rates (degrees per second; zoom: change of the field of view)."""
        ...

    def stop(self) -> None:
        """Stop every axis."""
        ...
