"""The live viewing rays: each new fix's ray with its terrain hits, and the tracker's choice.

The newest ``max_rays`` rays are kept and drawn under ``/rays/``: ``lines`` (each ray from
its origin to its farthest hit, in its sensor's colour), ``hits`` (every terrain hit, road
hit included) and ``chosen`` (the hit the tracker used, the one nearest the track point
made from that detection).
"""

from __future__ import annotations

import collections
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .style import HIT_COLOUR, SELECTED_COLOUR, hex_colour, sensor_colour

__all__ = ["RayLayer"]


@dataclass
class _Ray:
    det_id: int
    sensor: str
    origin: np.ndarray
    hits: np.ndarray  # (k, 3), road hit appended last when there is one
    chosen: int | None = None


class RayLayer:
    """The newest viewing rays and their drawing.

    Parameters
    ----------
    server : viser.ViserServer
        Where the rays are drawn.
    sensors : Mapping
        The site's sensors by id (their rank in id order picks a ray's colour).
    nodes : dict
        Scene node name -> viser handle, shared with the scene: drawn nodes go in.
    max_rays : int
        Newest rays kept.
    """

    def __init__(
        self, server: Any, sensors: Mapping[str, Any], nodes: dict[str, Any], max_rays: int
    ) -> None:
        self.server = server
        self.sensors = sensors
        self.nodes = nodes
        self.rays: collections.deque[_Ray] = collections.deque(maxlen=max_rays)
        self.dirty = False

    def add_fix(self, fix: dict[str, Any]) -> None:
        """Keep a fix's ray (a fix without hits has none to draw).

        Parameters
        ----------
        fix : dict
            A ``fix`` message's body: ``detection_id``, ``sensor``, ``origin_enu`` and its
            ``hits`` and ``road_hit`` (site frame ``e_m, n_m, u_m``).
        """
        hits = [[h["e_m"], h["n_m"], h["u_m"]] for h in fix.get("hits") or []]
        road = fix.get("road_hit")
        if road is not None:
            hits.append([road["e_m"], road["n_m"], road["u_m"]])
        if not hits:
            return
        ray = _Ray(
            int(fix["detection_id"]),
            str(fix["sensor"]),
            np.asarray(fix["origin_enu"], dtype=np.float64),
            np.asarray(hits, dtype=np.float64),
        )
        self.rays.append(ray)
        self.dirty = True

    def choose(self, points: Iterable[dict[str, Any]]) -> None:
        """Mark the tracker's choice among the hits of the rays track points were made from.

        Parameters
        ----------
        points : iterable of dict
            Track points (``e_m, n_m, u_m``, ``detection_ids``): each ray of one of
            their detections has the hit nearest the point chosen.
        """
        by_det = {r.det_id: r for r in self.rays}
        for p in points:
            for det in p.get("detection_ids", []):
                ray = by_det.get(int(det))
                if ray is not None:
                    q = np.array([p["e_m"], p["n_m"], p["u_m"]])
                    ray.chosen = int(np.argmin(np.linalg.norm(ray.hits - q, axis=1)))
                    self.dirty = True

    def render(self) -> None:
        """Redraw the rays, their hits and the chosen hits if anything changed."""
        if not (self.dirty and self.rays):
            return
        self.dirty = False
        scene = self.server.scene
        sensors = sorted(self.sensors)
        segs, colours, all_hits, chosen = [], [], [], []
        for r in self.rays:
            far = r.hits[np.argmax(np.linalg.norm(r.hits - r.origin, axis=1))]
            segs.append([r.origin, far])
            k = sensors.index(r.sensor) if r.sensor in sensors else 0
            colours.append([sensor_colour(k)] * 2)
            all_hits.append(r.hits)
            if r.chosen is not None:
                chosen.append(r.hits[r.chosen])
        self.nodes["/rays/lines"] = scene.add_line_segments(
            "/rays/lines",
            np.asarray(segs),
            np.asarray(colours, dtype=np.uint8),
            thickness=1.5,
            thickness_units="screen",
        )
        self.nodes["/rays/hits"] = scene.add_point_cloud(
            "/rays/hits",
            np.concatenate(all_hits).astype(np.float32),
            hex_colour(HIT_COLOUR),  # as the map's terrain hits
            point_size=1.5,
            point_shape="circle",
            precision="float32",
        )
        pts = np.asarray(chosen, dtype=np.float32).reshape(-1, 3)
        self.nodes["/rays/chosen"] = scene.add_point_cloud(
            "/rays/chosen",
            pts,
            hex_colour(SELECTED_COLOUR),  # as the map's chosen hit
            point_size=3.0,
            point_shape="circle",
            precision="float32",
        )
