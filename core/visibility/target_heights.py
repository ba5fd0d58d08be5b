"""Standing heights of the targets the system tracks, one table for every visibility question.

A viewshed cell, a hand-off prediction or a gap explanation asks whether a sight line reaches
a point this high above the DEM surface (m): the top of a standing person or of a car. The
CLI, the API, the live hand-off and the gap explanations all read it from here. This module
imports nothing heavy, so command-line parsers can use it for their defaults.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

__all__ = ["DEFAULT_TARGET_HEIGHT_M", "TARGET_HEIGHT_M", "target_height_for"]

#: Height of a standing target by class (m above the surface).
TARGET_HEIGHT_M: Mapping[str, float] = MappingProxyType({"human": 1.7, "vehicle": 1.5})

#: Target height when no class is given: a standing person, the taller of the two.
DEFAULT_TARGET_HEIGHT_M = TARGET_HEIGHT_M["human"]


def target_height_for(cls: str | None) -> float:
    """Height of a target of class ``cls`` (m); an unknown class counts as a vehicle."""
    return TARGET_HEIGHT_M.get(cls or "", TARGET_HEIGHT_M["vehicle"])
