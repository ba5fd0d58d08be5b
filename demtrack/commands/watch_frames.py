"""``demtrack watch --frames``: the camera's frames to the console server, best effort.

:class:`FramePoster` takes the frames whose detections the watch has just released
(each with its boxes, in the camera's pixels), keeps those at least ``1 / rate_hz``
seconds apart in video time, and posts each to ``PUT /api/sensors/{id}/frame`` from a
background thread: downscaled to at most 1280 px wide, JPEG quality 75, ``X-Frame-Time``
the frame's UTC. It never blocks the decoder and never touches the detections: a frame
offered while the previous one is still being sent replaces the waiting one, and a frame
that cannot be posted (server down, a refusal) is dropped, said once on stderr, and the
watch goes on.
"""

from __future__ import annotations

import json
import threading
import urllib.error
import urllib.request
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["FramePoster"]


class FramePoster:
    """Post frames in a background thread (see the module docstring).

    Parameters
    ----------
    url : str
        The server's base URL.
    sensor : str
    token : str, optional
    rate_hz : float
        Most frames per second of video time.
    max_width : int
        Wider frames are downscaled to this.
    log : callable
        One-line notes (stderr).
    """

    def __init__(
        self,
        url: str,
        sensor: str,
        token: str | None = None,
        *,
        rate_hz: float = 4.0,
        max_width: int = 1280,
        quality: int = 75,
        timeout_s: float = 5.0,
        log: Callable[[str], None] | None = None,
    ) -> None:
        self.url = f"{url.rstrip('/')}/api/sensors/{sensor}/frame"
        self.token = token
        self.every_s = 1.0 / float(rate_hz)
        self.max_width, self.quality, self.timeout_s = int(max_width), int(quality), timeout_s
        self.log = log or (lambda _m: None)
        self._last_t = -np.inf
        self._pending: tuple[float, np.ndarray, list[list[float]]] | None = None
        self._cond = threading.Condition()
        self._closed = False
        self._failing = False
        self.n_posted = self.n_dropped = self.n_failed = 0
        self._thread = threading.Thread(target=self._run, name="watch-frames", daemon=True)
        self._thread.start()

    def offer(self, t_s: float, image: np.ndarray, boxes: Sequence[Sequence[float]]) -> bool:
        """Hand over a frame (UTC ``t_s``); False when skipped by the rate limit."""
        if t_s - self._last_t < self.every_s - 1e-6:
            return False
        self._last_t = t_s
        with self._cond:
            if self._pending is not None:
                self.n_dropped += 1  # the sender is behind: the newest frame wins
            self._pending = (float(t_s), image, [list(map(float, b)) for b in boxes])
            self._cond.notify()
        return True

    def close(self, timeout_s: float = 5.0) -> None:
        """Send what waits, then stop the thread."""
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join(timeout_s)

    def _run(self) -> None:
        from demtrack.server.video.jpeg import encode_jpeg

        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                item, self._pending = self._pending, None
                if item is None:
                    return
            t_s, image, boxes = item
            try:
                jpeg = encode_jpeg(image, max_width=self.max_width, quality=self.quality)
                self._post(jpeg, t_s, boxes)
            except Exception as exc:  # noqa: BLE001 - frames are best effort, never fatal
                self.n_failed += 1
                if not self._failing:
                    self.log(f"frames not posted ({_why(exc)}); detections go on")
                    self._failing = True

    def _post(self, jpeg: bytes, t_s: float, boxes: list[list[float]]) -> None:
        headers = {
            "Content-Type": "image/jpeg",
            "X-Frame-Time": repr(t_s),
            "X-Frame-Boxes": json.dumps(boxes),
        }
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        req = urllib.request.Request(self.url, data=jpeg, headers=headers, method="PUT")
        with urllib.request.urlopen(req, timeout=self.timeout_s) as resp:
            resp.read()
        self.n_posted += 1
        if self._failing:
            self.log("frames are posted again")
            self._failing = False


def _why(exc: BaseException) -> str:
    if isinstance(exc, urllib.error.HTTPError):
        detail = exc.read().decode(errors="replace").strip()[:160]
        return f"HTTP {exc.code}: {detail}"
    text = str(getattr(exc, "reason", exc)).strip().splitlines()
    return text[0] if text else type(exc).__name__
