"""The decoded frames a video pipeline's detections belong to."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from typing import Any

from demtrack.core.video.reader import Frame, VideoReader

__all__ = ["FrameKeeper"]


class FrameKeeper:
    """A reader that remembers its last ``keep`` frames by index.

    :class:`~demtrack.core.video.pipeline.VideoDetections` releases a frame's detections
    a few frames after decoding it; this finds the frame they belong to. Reads KLV too
    when ``klv`` (``demtrack watch``); the replay reads none.
    """

    def __init__(self, reader: VideoReader, keep: int, *, klv: bool = False) -> None:
        self.reader = reader
        self.frames: dict[int, Frame] = {}
        self._order: deque[int] = deque()
        self.keep = keep
        self.klv = klv

    def items(self) -> Iterator[Any]:
        """The reader's items, remembering the frames."""
        for item in self.reader.items(klv=self.klv):
            if isinstance(item, Frame):
                self.frames[item.index] = item
                self._order.append(item.index)
                while len(self._order) > self.keep:
                    self.frames.pop(self._order.popleft(), None)
            yield item
