"""The newest video frame of each sensor, kept in memory.

Memory is bounded: one JPEG per sensor (of the site's sensors only, each at most
``max_bytes``), with its UTC time, its size and, when the poster knows them, the boxes
of the detections in that frame. Each stored frame gets an entity tag unique to this
book (a random book id and a counter), so a client polling ``frame.jpg`` with
``If-None-Match`` gets a 304 for nothing while the frame is unchanged, and never mistakes
a frame of an earlier server run for the current one. A frame older than the one held
is not stored (cameras posting out of order keep the newest).
"""

from __future__ import annotations

import math
import secrets
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from demtrack.core.errors import VideoError

from .jpeg import jpeg_size

__all__ = ["FrameBook", "StoredFrame"]

#: Boxes are ``(u_min, v_min, u_max, v_max)`` in pixels ((0, 0) the top-left pixel's centre).
Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class StoredFrame:
    """One sensor's newest frame.

    Attributes
    ----------
    sensor : str
    jpeg : bytes
        The JPEG as posted (or as the replay encoded it).
    t_s : float
        The frame's capture time, UNIX seconds UTC.
    etag : str
        The quoted entity tag of this frame.
    width, height : int
        Pixels of the JPEG (from its frame header).
    boxes : tuple of Box or None
        The detections' boxes in that frame, in the camera's pixels; None when unknown.
    received_s : float
        Wall clock (UNIX s) when the server stored it.
    """

    sensor: str
    jpeg: bytes
    t_s: float
    etag: str
    width: int
    height: int
    boxes: tuple[Box, ...] | None
    received_s: float


class FrameBook:
    """The newest frame per sensor (see the module docstring); thread-safe.

    Parameters
    ----------
    sensors : sequence of str
        The site's sensor ids: frames of any other sensor are refused.
    max_bytes : int
        Largest JPEG stored.
    clock : callable
        Wall clock, UNIX seconds.
    """

    def __init__(
        self,
        sensors: Sequence[str],
        *,
        max_bytes: int = 2 * 1024 * 1024,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.sensors = frozenset(sensors)
        self.max_bytes = int(max_bytes)
        self.clock = clock
        self._id = secrets.token_hex(4)
        self._n = 0
        self._frames: dict[str, StoredFrame] = {}
        self._lock = threading.Lock()
        self.n_put = 0
        self.n_older = 0

    def put(
        self,
        sensor: str,
        jpeg: bytes,
        t_s: float,
        boxes: Sequence[Sequence[float]] | None = None,
        *,
        check: bool = True,
    ) -> StoredFrame | None:
        """Store ``jpeg`` as ``sensor``'s frame at ``t_s``; None when it is older than the held one.

        ``check=False`` skips the JPEG check (frames this server encoded itself).

        Raises
        ------
        VideoError
            Not a JPEG, too large, a time that is not finite, or malformed boxes.
        KeyError
            A sensor the book does not know (the router answers 404 before this).
        """
        if sensor not in self.sensors:
            raise KeyError(sensor)
        if len(jpeg) > self.max_bytes:
            raise VideoError(f"frame is {len(jpeg)} bytes; the limit is {self.max_bytes}")
        if not math.isfinite(t_s):
            raise VideoError(f"frame time must be finite, got {t_s!r}")
        width, height = jpeg_size(jpeg) if check else (0, 0)
        kept = None if boxes is None else tuple(_box(b) for b in boxes)
        with self._lock:
            held = self._frames.get(sensor)
            if held is not None and t_s < held.t_s:
                self.n_older += 1
                return None
            self._n += 1
            frame = StoredFrame(
                sensor, bytes(jpeg), float(t_s), f'"{self._id}-{self._n}"', width, height,
                kept, self.clock(),
            )  # fmt: skip
            self._frames[sensor] = frame
            self.n_put += 1
        return frame

    @property
    def version(self) -> str:
        """A quoted tag that changes whenever any frame is stored (or forgotten)."""
        return f'"{self._id}-v{self._n}"'

    def index(self) -> tuple[str, dict[str, StoredFrame]]:
        """The book's version and its frames, read together."""
        with self._lock:
            return self.version, dict(self._frames)

    def get(self, sensor: str) -> StoredFrame | None:
        """``sensor``'s newest frame, or None."""
        return self._frames.get(sensor)

    def clear(self, sensor: str | None = None) -> None:
        """Forget one sensor's frame (or every frame)."""
        with self._lock:
            self._n += 1
            if sensor is None:
                self._frames.clear()
            else:
                self._frames.pop(sensor, None)


def _box(b: Sequence[float]) -> Box:
    try:
        u0, v0, u1, v1 = (float(x) for x in b)
    except (TypeError, ValueError):
        raise VideoError(f"a frame box must be [u_min, v_min, u_max, v_max], got {b!r}") from None
    if not all(math.isfinite(x) for x in (u0, v0, u1, v1)) or u1 < u0 or v1 < v0:
        raise VideoError(f"a frame box must be finite with u_max >= u_min, v_max >= v_min: {b!r}")
    return (u0, v0, u1, v1)
