"""Where CoT goes: ``udp://HOST:PORT[?ttl=N&iface=ADDR]`` or ``tcp://HOST:PORT``.

A UDP host in 224.0.0.0/4 is multicast (ATAK's default SA group is
``udp://239.2.3.1:6969``); ``ttl`` (1-255, default 1: the local network) is its
time-to-live and ``iface`` the local address whose interface sends it. TCP is TAK
Server's plain streaming input (``tcp://takserver:8087``).
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from demtrack.core.errors import SettingsError

__all__ = ["CotTarget", "parse_cot_url"]


@dataclass(frozen=True)
class CotTarget:
    """A parsed CoT destination.

    Attributes
    ----------
    scheme : str
        ``udp`` or ``tcp``.
    host : str
        Name or address.
    port : int
        1-65535.
    ttl : int
        Multicast time-to-live (UDP only).
    iface : str or None
        Local address of the multicast interface (UDP only; default: the system's).
    """

    scheme: str
    host: str
    port: int
    ttl: int = 1
    iface: str | None = None

    @property
    def multicast(self) -> bool:
        """A UDP address in 224.0.0.0/4."""
        try:
            return self.scheme == "udp" and ipaddress.ip_address(self.host).is_multicast
        except ValueError:
            return False

    def __str__(self) -> str:
        """The URL again."""
        return f"{self.scheme}://{self.host}:{self.port}"


def parse_cot_url(url: str) -> CotTarget:
    """Parse a CoT URL.

    Raises
    ------
    SettingsError
        One line naming what is wrong (scheme, host, port, ttl, iface, other options).
    """
    text = str(url).strip()
    hint = "expected udp://HOST:PORT[?ttl=N] or tcp://HOST:PORT, e.g. udp://239.2.3.1:6969"
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError as exc:
        raise SettingsError(f"CoT URL {text!r}: {exc}; {hint}") from None
    if parts.scheme not in ("udp", "tcp"):
        raise SettingsError(f"CoT URL {text!r}: scheme must be udp or tcp; {hint}")
    if not parts.hostname:
        raise SettingsError(f"CoT URL {text!r}: no host; {hint}")
    if port is None or not 1 <= port <= 65535:
        raise SettingsError(f"CoT URL {text!r}: a port from 1 to 65535 is needed; {hint}")
    if parts.path not in ("", "/") or parts.fragment or parts.username:
        raise SettingsError(f"CoT URL {text!r}: only HOST:PORT and ?ttl=/iface= are read; {hint}")
    try:
        query = parse_qs(parts.query, strict_parsing=bool(parts.query))
    except ValueError:
        raise SettingsError(f"CoT URL {text!r}: malformed query; {hint}") from None
    unknown = sorted(set(query) - {"ttl", "iface"})
    if unknown or (query and parts.scheme == "tcp"):
        what = ", ".join(unknown) if unknown else ", ".join(sorted(query))
        raise SettingsError(f"CoT URL {text!r}: unknown option {what} for {parts.scheme}")
    ttl = 1
    if "ttl" in query:
        raw = query["ttl"][-1]
        if not raw.isdigit() or not 1 <= int(raw) <= 255:
            raise SettingsError(f"CoT URL {text!r}: ttl must be an integer from 1 to 255")
        ttl = int(raw)
    iface = None
    if "iface" in query:
        iface = query["iface"][-1]
        try:
            ipaddress.IPv4Address(iface)
        except ValueError:
            raise SettingsError(f"CoT URL {text!r}: iface must be an IPv4 address") from None
    return CotTarget(parts.scheme, parts.hostname, port, ttl, iface)
