"""Colours of the scene: the console's palette (``web/console/palette.mjs``).

Tracks are coloured by class as on the map (vehicle orange, human cyan; ended ones dimmed),
the followed track in the selection yellow, terrain hits in the hit magenta, and each
sensor's frustum and rays in that camera's own colour, by its rank in sorted id order
(its footprint, map symbol, viewshed and panel share it). ``tests/web/test_console_palette.py``
fails when these values and the console's differ.
"""

from __future__ import annotations

__all__ = [
    "CLASS_COLOURS",
    "HIT_COLOUR",
    "SELECTED_COLOUR",
    "SENSOR_COLOURS",
    "class_colour",
    "hex_colour",
    "sensor_colour",
]


def hex_colour(rgb: str) -> tuple[int, int, int]:
    """``"#rrggbb"`` as ``(r, g, b)``, 0-255."""
    n = int(rgb.lstrip("#"), 16)
    return (n >> 16) & 255, (n >> 8) & 255, n & 255


#: Target classes (palette.mjs CLASS_COLOURS).
CLASS_COLOURS: dict[str, str] = {"vehicle": "#ff7a1a", "human": "#1ad0ff"}
UNKNOWN_CLASS_COLOUR = "#cccccc"
#: The selected (followed) track (palette.mjs SELECTED_COLOUR).
SELECTED_COLOUR = "#ffe600"
#: Terrain hits (palette.mjs HIT_COLOUR).
HIT_COLOUR = "#ff2bd6"
#: Per-camera colours by rank in sorted id order (palette.mjs SENSOR_COLOURS).
SENSOR_COLOURS: tuple[str, ...] = ("#10a078", "#b07090", "#909030", "#10f0d0")

_FOLLOW_COLOUR = hex_colour(SELECTED_COLOUR)


def class_colour(cls: str) -> tuple[int, int, int]:
    """A track's colour (RGB 0-255) by its class, as on the map."""
    return hex_colour(CLASS_COLOURS.get(cls, UNKNOWN_CLASS_COLOUR))


def sensor_colour(rank: int) -> tuple[int, int, int]:
    """The colour (RGB 0-255) of a sensor's frustum and rays, by its rank in id order."""
    return hex_colour(SENSOR_COLOURS[rank % len(SENSOR_COLOURS)])
