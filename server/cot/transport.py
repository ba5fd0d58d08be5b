"""Sending CoT events: one UDP datagram each, or a TCP stream that reconnects.

UDP (unicast or multicast): each event is one datagram with its XML declaration, as ATAK
sends and reads SA. TCP: events back to back with no declaration and no separator
(TAK Server's streaming input parses consecutive ``<event>`` elements); a broken
connection is closed and reopened on the next event, no sooner than a back-off that
doubles from 0.5 s up to 10 s; an event met while disconnected is dropped, never queued,
so a TAK server that is down costs nothing but the events it would have shown. Every
socket has a send timeout: a peer that stops reading breaks the connection instead of
holding the sender.
"""

from __future__ import annotations

import logging
import socket
import time
from typing import Protocol

from .target import CotTarget

__all__ = ["TcpTransport", "Transport", "UdpTransport", "open_transport"]

log = logging.getLogger("demtrack.server.cot")


class Transport(Protocol):
    """Sends one encoded event; true when it left, false when it was dropped."""

    def send(self, event_xml: bytes) -> bool:
        """Send ``event_xml`` (one ``<event>`` element, no declaration)."""
        ...

    def close(self) -> None:
        """Release the socket."""
        ...


_DECL = b'<?xml version="1.0" encoding="UTF-8"?>'


class UdpTransport:
    """One datagram per event to a unicast or multicast address."""

    def __init__(self, target: CotTarget, timeout_s: float = 1.0) -> None:
        self.target = target
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(timeout_s)
        if target.multicast:
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, target.ttl)
            self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            if target.iface:
                self.sock.setsockopt(
                    socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(target.iface)
                )
        self.addr = (target.host, target.port)

    def send(self, event_xml: bytes) -> bool:
        """Send one datagram; false (logged once per kind) when the system refuses it."""
        try:
            self.sock.sendto(_DECL + event_xml, self.addr)
            return True
        except OSError as exc:
            log.debug("CoT datagram to %s not sent: %s", self.target, exc)
            return False

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()


class TcpTransport:
    """A TCP stream of bare events that reconnects after a failure."""

    def __init__(
        self,
        target: CotTarget,
        timeout_s: float = 2.0,
        backoff_s: float = 0.5,
        max_backoff_s: float = 10.0,
    ) -> None:
        self.target = target
        self.timeout_s = timeout_s
        self.min_backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self.backoff_s = backoff_s
        self.sock: socket.socket | None = None
        self.next_try = 0.0
        self.n_connects = 0

    def _connect(self) -> socket.socket | None:
        now = time.monotonic()
        if now < self.next_try:
            return None
        try:
            sock = socket.create_connection(
                (self.target.host, self.target.port), timeout=self.timeout_s
            )
        except OSError as exc:
            self.next_try = now + self.backoff_s
            self.backoff_s = min(2 * self.backoff_s, self.max_backoff_s)
            log.debug("CoT: cannot connect to %s: %s", self.target, exc)
            return None
        sock.settimeout(self.timeout_s)
        self.sock = sock
        self.backoff_s = self.min_backoff_s
        self.n_connects += 1
        log.info("CoT: connected to %s", self.target)
        return sock

    def _drop(self) -> None:
        if self.sock is not None:
            try:
                self.sock.close()
            finally:
                self.sock = None
        self.next_try = time.monotonic() + self.backoff_s

    def send(self, event_xml: bytes) -> bool:
        """Send one event on the stream, connecting first if needed; false if dropped."""
        sock = self.sock if self.sock is not None else self._connect()
        if sock is None:
            return False
        try:
            sock.sendall(event_xml)
            return True
        except OSError as exc:  # reset, broken pipe, or a peer that stopped reading
            log.info("CoT: connection to %s lost (%s); reconnecting", self.target, exc)
            self._drop()
            return False

    def close(self) -> None:
        """Close the stream."""
        self._drop()


def open_transport(target: CotTarget) -> UdpTransport | TcpTransport:
    """The transport for ``target``'s scheme."""
    return UdpTransport(target) if target.scheme == "udp" else TcpTransport(target)
