"""An ONVIF PTZ head: :class:`~.adapter.HeadAdapter` over SOAP 1.2 and plain HTTP.

ONVIF positions are normalised (pan and tilt -1..1, zoom 0..1); :class:`OnvifMapping`
maps them to degrees by the head's configuration: the pan and tilt ranges that -1..1
span, and the field of view at zoom 0 (wide) and 1 (tele). Zoom is linear in focal
length by default (``zoom_scale: "focal"``: ``1/tan(hfov/2)`` linear in the zoom value,
what most zoom lenses' position encoders are close to), or linear in the field of view
(``"hfov"``). Velocities are -1..1 of the speeds the configuration names.

Every call has a timeout; a refused connection, a timeout, an HTTP error, a SOAP fault or
an answer that cannot be read is one :class:`~.adapter.HeadAdapterError` naming the head,
the operation and the cause -- never a hang.
"""

from __future__ import annotations

import math
import time
import urllib.error
import urllib.request
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from demtrack.core.camera.pantilt import wrap_deg

from .adapter import HeadAdapterError, HeadStatus
from .onvif_soap import PtzPosition, SoapFault, envelope, parse_envelope, parse_status, request_body

__all__ = ["OnvifHead", "OnvifMapping"]


def _clip(x: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, x))


@dataclass(frozen=True)
class OnvifMapping:
    """Normalised ONVIF PTZ values <-> degrees for one head.

    Parameters
    ----------
    pan_range_deg : (float, float)
        Pan (degrees clockwise from the mount's zero) at x = -1 and x = +1.
    tilt_range_deg : (float, float)
        Tilt (degrees, positive up) at y = -1 and y = +1.
    hfov_deg : (float, float)
        Horizontal field of view at zoom 0 (wide) and zoom 1 (tele), degrees.
    zoom_scale : {"focal", "hfov"}
        Zoom linear in focal length or in field of view.
    pan_speed_deg_s, tilt_speed_deg_s, zoom_speed_deg_s : float
        The speeds a velocity of 1 means (degrees per second; zoom: of the field of view).
    """

    pan_range_deg: tuple[float, float] = (-180.0, 180.0)
    tilt_range_deg: tuple[float, float] = (-90.0, 30.0)
    hfov_deg: tuple[float, float] = (60.0, 3.0)
    zoom_scale: str = "focal"
    pan_speed_deg_s: float = 60.0
    tilt_speed_deg_s: float = 40.0
    zoom_speed_deg_s: float = 10.0

    def __post_init__(self) -> None:
        for name in ("pan_range_deg", "tilt_range_deg", "hfov_deg"):
            pair = tuple(float(v) for v in getattr(self, name))
            if len(pair) != 2 or pair[0] == pair[1] or not all(map(math.isfinite, pair)):
                raise HeadAdapterError(f"ONVIF {name} must be two different numbers, got {pair}")
            object.__setattr__(self, name, pair)
        if not all(0.0 < h < 180.0 for h in self.hfov_deg):
            raise HeadAdapterError(f"ONVIF hfov_deg must lie in (0, 180), got {self.hfov_deg}")
        if self.zoom_scale not in ("focal", "hfov"):
            raise HeadAdapterError(
                f"ONVIF zoom_scale must be 'focal' or 'hfov', got {self.zoom_scale!r}"
            )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> OnvifMapping:
        """The mapping keys of a ``head_adapter`` entry (others are ignored)."""
        keys = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        try:
            return cls(**keys)
        except (TypeError, ValueError) as exc:
            raise HeadAdapterError(f"ONVIF head mapping: {exc}") from None

    # pan / tilt ----------------------------------------------------------------
    def pan_to_x(self, pan_deg: float) -> float:
        """ONVIF pan x (-1..1, clipped) of a pan (degrees).

        The copy of the pan (modulo 360) that lies inside the range is used: a head whose
        range is 0..350 reads pan -20 as 340.
        """
        lo, hi = sorted(self.pan_range_deg)
        p = pan_deg
        for candidate in (pan_deg, pan_deg + 360.0, pan_deg - 360.0):
            if lo <= candidate <= hi:
                p = candidate
                break
        a, b = self.pan_range_deg
        return _clip(-1.0 + 2.0 * (p - a) / (b - a), -1.0, 1.0)

    def x_to_pan(self, x: float) -> float:
        """Pan (degrees, in (-180, 180]) of an ONVIF pan x."""
        lo, hi = self.pan_range_deg
        return float(wrap_deg(lo + (x + 1.0) / 2.0 * (hi - lo)))

    def tilt_to_y(self, tilt_deg: float) -> float:
        """ONVIF tilt y (-1..1, clipped) of a tilt (degrees)."""
        lo, hi = self.tilt_range_deg
        return _clip(-1.0 + 2.0 * (tilt_deg - lo) / (hi - lo), -1.0, 1.0)

    def y_to_tilt(self, y: float) -> float:
        """Tilt (degrees) of an ONVIF tilt y."""
        lo, hi = self.tilt_range_deg
        return lo + (y + 1.0) / 2.0 * (hi - lo)

    # zoom ----------------------------------------------------------------------
    def _k(self, hfov_deg: float) -> float:
        if self.zoom_scale == "hfov":
            return hfov_deg
        return 1.0 / math.tan(math.radians(hfov_deg) / 2.0)

    def hfov_to_zoom(self, hfov_deg: float) -> float:
        """ONVIF zoom (0..1, clipped) of a horizontal field of view (degrees)."""
        wide, tele = self.hfov_deg
        k_w, k_t = self._k(wide), self._k(tele)
        return _clip((self._k(hfov_deg) - k_w) / (k_t - k_w), 0.0, 1.0)

    def zoom_to_hfov(self, zoom: float) -> float:
        """Horizontal field of view (degrees) of an ONVIF zoom value."""
        wide, tele = self.hfov_deg
        k = self._k(wide) + zoom * (self._k(tele) - self._k(wide))
        return k if self.zoom_scale == "hfov" else math.degrees(2.0 * math.atan(1.0 / k))


class OnvifHead:
    """An ONVIF PTZ head.

    Parameters
    ----------
    url : str
        The PTZ service address (``http://camera/onvif/ptz_service``).
    profile : str
        The media profile token the PTZ configuration belongs to.
    mapping : OnvifMapping
        Normalised values <-> degrees.
    user, password : str, optional
        WS-Security UsernameToken (digest) credentials.
    timeout_s : float
        Timeout of every HTTP call (s).
    """

    def __init__(
        self,
        url: str,
        profile: str,
        mapping: OnvifMapping | None = None,
        *,
        user: str | None = None,
        password: str | None = None,
        timeout_s: float = 2.0,
    ) -> None:
        if not url.startswith(("http://", "https://")):
            raise HeadAdapterError(f"ONVIF url must be http:// or https://, got {url!r}")
        self.url, self.profile = url, profile
        self.mapping = mapping or OnvifMapping()
        self.user, self.password = user, password
        self.timeout_s = float(timeout_s)

    def _call(self, operation: str, vector: PtzPosition | None = None) -> Any:
        data = envelope(request_body(operation, self.profile, vector), self.user, self.password)
        action = f"http://www.onvif.org/ver20/ptz/wsdl/{operation}"
        req = urllib.request.Request(
            self.url,
            data=data,
            method="POST",
            headers={"Content-Type": f'application/soap+xml; charset=utf-8; action="{action}"'},
        )
        where = f"ONVIF head {self.url} {operation}"
        try:
            with urllib.request.urlopen(req, timeout=self.timeout_s) as resp:  # noqa: S310
                body = resp.read()
        except urllib.error.HTTPError as exc:  # a fault usually comes with HTTP 400 or 500
            body = exc.read()
            try:
                parse_envelope(body)
            except SoapFault as fault:
                raise HeadAdapterError(f"{where}: SOAP fault {fault}") from None
            except ValueError:
                pass
            raise HeadAdapterError(f"{where}: HTTP {exc.code} {exc.reason}") from None
        except (urllib.error.URLError, TimeoutError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            if isinstance(reason, TimeoutError) or isinstance(exc, TimeoutError):
                raise HeadAdapterError(f"{where}: no answer within {self.timeout_s:g} s") from None
            raise HeadAdapterError(f"{where}: {reason}") from None
        try:
            _, first = parse_envelope(body)
        except SoapFault as fault:
            raise HeadAdapterError(f"{where}: SOAP fault {fault}") from None
        except ValueError as exc:
            raise HeadAdapterError(f"{where}: {exc}") from None
        return first

    def status(self) -> HeadStatus:
        """``GetStatus``, in degrees; the head's ``UtcTime`` when it sends one."""
        t_sent = time.time()
        first = self._call("GetStatus")
        t_got = time.time()
        try:
            pos, moving, utc = parse_status(first)
            t_s = datetime.fromisoformat(utc.replace("Z", "+00:00")).timestamp() if utc else None
        except ValueError as exc:
            raise HeadAdapterError(f"ONVIF head {self.url} GetStatus: {exc}") from None
        m = self.mapping
        hfov = m.zoom_to_hfov(pos.zoom) if pos.zoom is not None else m.hfov_deg[0]
        return HeadStatus(
            t_s if t_s is not None else 0.5 * (t_sent + t_got),
            m.x_to_pan(pos.pan),
            m.y_to_tilt(pos.tilt),
            hfov,
            moving,
        )

    def absolute_move(self, pan_deg: float, tilt_deg: float, hfov_deg: float | None) -> None:
        """``AbsoluteMove`` to a pan and tilt (degrees) and, unless ``None``, a field of view."""
        m = self.mapping
        zoom = None if hfov_deg is None else m.hfov_to_zoom(hfov_deg)
        self._call("AbsoluteMove", PtzPosition(m.pan_to_x(pan_deg), m.tilt_to_y(tilt_deg), zoom))

    def continuous_move(
        self, pan_rate_deg_s: float, tilt_rate_deg_s: float, zoom_rate_deg_s: float
    ) -> None:
        """``ContinuousMove`` at these rates (degrees per second; zoom: of the field of view).

        A positive zoom rate widens the view, i.e. a negative ONVIF zoom velocity.
        """
        m = self.mapping
        v = PtzPosition(
            _clip(pan_rate_deg_s / m.pan_speed_deg_s, -1.0, 1.0),
            _clip(tilt_rate_deg_s / m.tilt_speed_deg_s, -1.0, 1.0),
            _clip(-zoom_rate_deg_s / m.zoom_speed_deg_s, -1.0, 1.0),
        )
        self._call("ContinuousMove", v)

    def stop(self) -> None:
        """``Stop`` pan, tilt and zoom."""
        self._call("Stop")
