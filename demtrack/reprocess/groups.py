"""Sensor groups: connected components of footprint overlap.

Two sensors belong to one group when the ground they see overlaps, within a margin
(a target leaving one field of view may be re-acquired in the other). What a sensor
sees is its viewshed (:func:`demtrack.core.visibility.viewshed.viewshed`): the current
field of view of a fixed camera, everything its head can reach for an ``active`` one
(a pan-tilt-zoom head that follows targets). Groups share no field of view, so they are
tracked apart, in parallel; a target is never seen by two groups at once.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from scipy import ndimage

from demtrack.core.site.folder import Site
from demtrack.core.visibility.viewshed import PanTiltLimits, viewshed

__all__ = ["groups_of_masks", "sensor_groups", "sensor_masks"]


def sensor_masks(
    site: Site, sensors: Iterable[str], *, max_range_m: float = 1000.0, target_height_m: float = 0.0
) -> dict[str, np.ndarray]:
    """Each sensor's seen cells (bool, ``site.dem.grid.shape``)."""
    out = {}
    for sid in sorted(sensors):
        sensor = site.sensors[sid]
        common = dict(target_height_m=target_height_m, max_range_m=max_range_m)
        if sensor.active:
            out[sid] = viewshed(
                site.dem, sensor.camera, mode="reachable",
                mount_yaw_deg=sensor.head.mount_yaw_deg, limits=PanTiltLimits(), **common,
            )  # fmt: skip
        else:
            out[sid] = viewshed(site.dem, sensor.camera, mode="fov", **common)  # type: ignore[arg-type]
    return out


def groups_of_masks(masks: dict[str, np.ndarray], margin_cells: int) -> list[tuple[str, ...]]:
    """Connected components of "the masks, grown by ``margin_cells``, overlap".

    Returns
    -------
    list of tuple of str
        Each group's sensor ids sorted; groups sorted by their first id.
    """
    ids = sorted(masks)
    structure = np.ones((3, 3), bool)
    grown = {
        s: ndimage.binary_dilation(m, structure, iterations=margin_cells) if margin_cells else m
        for s, m in masks.items()
    }
    parent = {s: s for s in ids}

    def root(s: str) -> str:
        while parent[s] != s:
            parent[s] = parent[parent[s]]
            s = parent[s]
        return s

    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            if np.any(grown[a] & grown[b]):
                ra, rb = root(a), root(b)
                parent[max(ra, rb)] = min(ra, rb)
    comps: dict[str, list[str]] = {}
    for s in ids:
        comps.setdefault(root(s), []).append(s)
    return sorted(tuple(sorted(c)) for c in comps.values())


def sensor_groups(
    site: Site, sensors: Iterable[str] | None = None, *, margin_m: float = 10.0,
    max_range_m: float = 1000.0,
) -> list[tuple[str, ...]]:  # fmt: skip
    """The site's sensor groups (:func:`groups_of_masks` of :func:`sensor_masks`).

    Parameters
    ----------
    site : Site
    sensors : iterable of str, optional
        Which sensors (default all).
    margin_m : float
        Fields of view closer than this (m) count as overlapping.
    max_range_m : float
        Ground farther from a camera than this does not count as seen.
    """
    ids = sorted(site.sensors if sensors is None else sensors)
    masks = sensor_masks(site, ids, max_range_m=max_range_m)
    cells = int(np.ceil(margin_m / float(site.dem.grid.cell_m)))
    return groups_of_masks(masks, cells)
