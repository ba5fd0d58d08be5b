"""Colours of the scene: tracks by id, sensors by rank, the followed track's yellow."""

from __future__ import annotations

import numpy as np

__all__ = ["sensor_colour", "track_colour"]

_PALETTE = np.array(
    [
        (230, 25, 75),
        (60, 180, 75),
        (0, 130, 200),
        (245, 130, 48),
        (145, 30, 180),
        (70, 240, 240),
        (240, 50, 230),
        (210, 245, 60),
        (0, 128, 128),
        (170, 110, 40),
    ],
    dtype=np.uint8,
)
_SENSOR_COLOURS = [(255, 215, 0), (0, 200, 255), (255, 105, 180), (160, 255, 120)]
_FOLLOW_COLOUR = (255, 230, 0)  # the console's selection colour


def track_colour(track_id: int) -> tuple[int, int, int]:
    """A track's colour (RGB 0-255), fixed by its id."""
    c = _PALETTE[int(track_id) % len(_PALETTE)]
    return int(c[0]), int(c[1]), int(c[2])


def sensor_colour(rank: int) -> tuple[int, int, int]:
    """The colour (RGB 0-255) of a sensor's frustum and rays, by its rank in id order."""
    return _SENSOR_COLOURS[rank % len(_SENSOR_COLOURS)]
