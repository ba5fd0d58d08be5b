"""Sample-site video: what a fixed camera sees during a scenario, with its true boxes.

Each frame starts from the camera's static scene (:mod:`.video_scene`: the draped
terrain, the DEM depth image, the crowns' sway field). The tree crowns sway (each tree
its own frequency and phase, with slow gusts); the targets of the scenario are drawn as
flat-shaded boxes (sun from the site renderer's direction, the same haze with range),
each pixel's ray intersected with each box exactly, and a box pixel is drawn only where
the box is nearer than every other box and no more than 1 m behind the DEM's surface
along that ray - the rule :func:`~.scenarios.image_boxes` uses for its sample points
(the 1 m absorbs the DEM's centimetres where a ray grazes the ground at a target's
feet). Then the whole frame takes a slow illumination drift (a gain of a few per cent)
and Gaussian sensor noise.

The truth comes from the same pixels: a target's box is the extent of its drawn pixels
(each pixel a unit square, pixel (0, 0) centred on (0, 0): ``(u_min - 0.5, v_min - 0.5,
u_max + 0.5, v_max + 0.5)``), its visible fraction the share of its pixels left after
occlusion. A box within :data:`BORDER_PX` of the image border is cut by it, and like a
box less than :data:`MIN_VISIBLE` visible, is not counted (the scenarios' rules).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from .scenarios import Target
from .video_scene import BoxPose, CameraScene, box_corners, box_hits
from .world import World

__all__ = [
    "BORDER_PX",
    "MIN_VISIBLE",
    "FrameRenderer",
    "RenderLook",
    "TargetTruth",
    "frame_times",
    "pose_at",
]

#: A box this close to the image border (px) is cut by it and not counted.
BORDER_PX = 2.0
#: A box with less than this share of its pixels visible is not counted.
MIN_VISIBLE = 0.3
#: A target pixel up to this far behind the DEM surface along its ray is still drawn (m).
DEPTH_MARGIN_M = 1.0
#: Haze of the site renderer (:func:`demtrack.core.site.render.render_view`'s defaults).
HAZE_M = 2500.0
HAZE_RGB = np.array([200.0, 215.0, 230.0], dtype=np.float32)

_VEHICLE_RGB = ((165, 32, 30), (45, 68, 150), (225, 225, 220), (35, 35, 38))
_SHIRT_RGB = ((200, 60, 50), (235, 205, 60), (60, 140, 70), (240, 240, 240))
_TROUSERS_RGB = np.array([55, 58, 80], dtype=np.float32)
_SKIN_RGB = np.array([205, 160, 130], dtype=np.float32)
_GLASS_RGB = np.array([40, 46, 58], dtype=np.float32)


@dataclass(frozen=True)
class RenderLook:
    """How the picture is degraded.

    Parameters
    ----------
    noise_sigma : float
        1-sigma Gaussian sensor noise per channel (0..255 scale).
    drift : float
        Amplitude of the slow illumination gain drift (fraction, e.g. 0.05 = 5 %).
    drift_period_s : float
        Period of the slowest drift component (s).
    sway : float
        Scale of the crowns' sway (1 = :data:`~.video_scene.SWAY_M` along the wind).
    sun_az_deg, sun_elev_deg : float
        Sun direction for the boxes' flat shading (the site renderer's defaults).
    """

    noise_sigma: float = 2.0
    drift: float = 0.05
    drift_period_s: float = 50.0
    sway: float = 1.0
    sun_az_deg: float = 200.0
    sun_elev_deg: float = 45.0

    @property
    def sun(self) -> np.ndarray:
        """Unit vector towards the sun (ENU)."""
        az, el = math.radians(self.sun_az_deg), math.radians(self.sun_elev_deg)
        return np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])


@dataclass(frozen=True)
class TargetTruth:
    """One target in one frame, as drawn.

    Parameters
    ----------
    target_id : int
    cls : str
        ``vehicle`` or ``human``.
    bbox : tuple of 4 float or None
        ``(u_min, v_min, u_max, v_max)`` of the drawn pixels' squares (px); None when
        nothing of it is drawn.
    visible_fraction : float
        Drawn pixels over the pixels it would cover with nothing in front.
    cut : bool
        The box is within :data:`BORDER_PX` of the image border.
    """

    target_id: int
    cls: str
    bbox: tuple[float, float, float, float] | None
    visible_fraction: float
    cut: bool

    @property
    def counted(self) -> bool:
        """A box the detector must find (visible enough, not cut by the border)."""
        return self.bbox is not None and not self.cut and self.visible_fraction >= MIN_VISIBLE


def frame_times(t_from_s: float, t_to_s: float, rate_hz: float) -> np.ndarray:
    """Frame times from ``t_from_s`` to ``t_to_s`` (inclusive, to 1 us) at ``rate_hz`` (s)."""
    n = int(math.floor((t_to_s - t_from_s) * rate_hz + 1e-6)) + 1
    return t_from_s + np.arange(max(n, 0)) / rate_hz


def pose_at(target: Target, world: World, t_s: float) -> BoxPose | None:
    """The target's box at scenario time ``t_s``; None outside its motion's time span."""
    m = target.motion
    if not m.t_start <= t_s <= m.t_end:
        return None
    xy, head = m.pose(np.array([t_s]))
    x, y = float(xy[0, 0]), float(xy[0, 1])
    hx, hy = float(head[0, 0]), float(head[0, 1])
    norm = math.hypot(hx, hy) or 1.0
    e = 0.25
    gz = world.ground_z(np.array([x + e, x - e, x, x]), np.array([y, y, y + e, y - e]))
    slope = (float(gz[0] - gz[1]) / (2 * e), float(gz[2] - gz[3]) / (2 * e))
    z0 = float(world.ground_z(x, y))
    return BoxPose((x, y), (hx / norm, hy / norm), target.size_m, z0, slope)


def _palette(target: Target) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper colour of a target (float RGB)."""
    k = (target.target_id - 1) % 4
    if target.cls == "vehicle":
        return np.array(_VEHICLE_RGB[k], dtype=np.float32), _GLASS_RGB
    return _TROUSERS_RGB, np.array(_SHIRT_RGB[k], dtype=np.float32)


class FrameRenderer:
    """Render the frames of one fixed camera.

    Parameters
    ----------
    scene : CameraScene
        The camera's static view.
    world : World
        The analytic world (target heights stand on its ground).
    targets : sequence of Target
        The scenario's targets.
    seed : int
        Seed of the noise, the crowns' sway and the drift's phase.
    look : RenderLook, optional
    """

    def __init__(
        self,
        scene: CameraScene,
        world: World,
        targets: Sequence[Target],
        seed: int = 0,
        look: RenderLook | None = None,
    ) -> None:
        self.scene = scene
        self.world = world
        self.targets = list(targets)
        self.look = RenderLook() if look is None else look
        self._rng = np.random.default_rng(seed)
        n_trees = max(len(world.trees), 1)
        self._sway_hz = self._rng.uniform(0.25, 0.6, n_trees)
        self._sway_phase = self._rng.uniform(0, 2 * np.pi, (2, n_trees))
        self._drift_phase = self._rng.uniform(0, 2 * np.pi, 2)
        self._origin = np.asarray(scene.camera.position_enu, dtype=np.float64)

    def gain(self, t_s: float) -> float:
        """Illumination gain at scenario time ``t_s`` (1 = the static render)."""
        lk = self.look
        p1, p2 = self._drift_phase
        w = 2 * math.pi / lk.drift_period_s
        return 1.0 + lk.drift * (0.7 * math.sin(w * t_s + p1) + 0.3 * math.sin(2.9 * w * t_s + p2))

    def _swayed(self, t_s: float) -> np.ndarray:
        """The background with the crowns moved to their place at ``t_s`` (float32 copy)."""
        sc = self.scene
        img = sc.background.copy()
        if not len(sc.sway_rows) or self.look.sway == 0:
            return img
        ph0, ph1 = self._sway_phase
        gust = 0.7 + 0.3 * np.sin(2 * np.pi * 0.05 * t_s + ph1)
        s = self.look.sway * gust * np.sin(2 * np.pi * self._sway_hz * t_s + ph0)
        s_px = s[sc.sway_tree].astype(np.float32)
        h, w = sc.shape
        # Each pixel shows the crown point that has swayed onto it (bilinear).
        su = np.clip(sc.sway_cols - sc.sway_du * s_px, 0, w - 1.001)
        sv = np.clip(sc.sway_rows - sc.sway_dv * s_px, 0, h - 1.001)
        j0, i0 = su.astype(np.intp), sv.astype(np.intp)
        fu, fv = (su - j0)[:, None], (sv - i0)[:, None]
        bg = sc.background
        top = bg[i0, j0] * (1 - fu) + bg[i0, j0 + 1] * fu
        bottom = bg[i0 + 1, j0] * (1 - fu) + bg[i0 + 1, j0 + 1] * fu
        img[sc.sway_rows, sc.sway_cols] = top * (1 - fv) + bottom * fv
        return img

    def _box_region(self, pose: BoxPose) -> tuple[slice, slice] | None:
        """Image rows and columns that may show the box (its corners' extent, padded)."""
        u, v, in_front = self.scene.camera.project(box_corners(pose))
        if not in_front.all() or not (np.isfinite(u).all() and np.isfinite(v).all()):
            return None
        h, w = self.scene.shape
        j0, j1 = max(int(np.floor(u.min())) - 2, 0), min(int(np.ceil(u.max())) + 3, w)
        i0, i1 = max(int(np.floor(v.min())) - 2, 0), min(int(np.ceil(v.max())) + 3, h)
        if j0 >= j1 or i0 >= i1:
            return None
        return slice(i0, i1), slice(j0, j1)

    def render(self, t_s: float) -> tuple[np.ndarray, list[TargetTruth]]:
        """The frame at scenario time ``t_s`` and the truth of the targets in view.

        Returns
        -------
        image : ndarray, uint8, shape (h, w, 3)
            RGB.
        truth : list of TargetTruth
            Targets with at least one pixel on the image (hidden ones included).
        """
        sc = self.scene
        img = self._swayed(t_s)
        drawn = []
        for tg in self.targets:
            pose = pose_at(tg, self.world, t_s)
            region = None if pose is None else self._box_region(pose)
            if pose is None or region is None:
                continue
            rng_m, normal, height = box_hits(pose, self._origin, sc.directions[region])
            if np.isfinite(rng_m).any():
                drawn.append((tg, region, rng_m, normal, height))
        # Boxes against each other: a depth buffer over the frame.
        zbuf = np.full(sc.shape, np.inf)
        for _, region, rng_m, _, _ in drawn:
            np.minimum(zbuf[region], rng_m, out=zbuf[region])
        truth = []
        sun = self.look.sun
        h, w = sc.shape
        for tg, region, rng_m, normal, height in drawn:
            full = np.isfinite(rng_m)
            seen = full & (rng_m <= zbuf[region]) & (rng_m <= sc.range_m[region] + DEPTH_MARGIN_M)
            n_full, n_seen = int(full.sum()), int(seen.sum())
            bbox = None
            cut = False
            if n_seen:
                lower, upper = _palette(tg)
                split = 0.55 if tg.cls == "vehicle" else 0.47
                hh = height[seen][:, None]
                colour = np.where(hh < split, lower, upper)
                if tg.cls == "vehicle":  # a body-coloured roof above a band of windows
                    roof = (np.abs(normal[seen][:, 2]) > 0.5)[:, None]
                    colour = np.where(roof | (hh > 0.92), lower, colour)
                else:
                    colour = np.where(hh > 0.86, _SKIN_RGB, colour)
                lambert = np.clip(normal[seen] @ sun, 0.0, 1.0)
                shaded = colour * (0.55 + 0.6 * lambert)[:, None]
                fade = (1.0 - np.exp(-rng_m[seen] / HAZE_M))[:, None]
                patch = img[region]
                patch[seen] = shaded * (1 - fade) + HAZE_RGB * fade
                img[region] = patch
                rows, cols = np.nonzero(seen)
                i0, j0 = region[0].start, region[1].start
                bbox = (
                    float(j0 + cols.min() - 0.5),
                    float(i0 + rows.min() - 0.5),
                    float(j0 + cols.max() + 0.5),
                    float(i0 + rows.max() + 0.5),
                )
                cut = (
                    bbox[0] < BORDER_PX - 0.5
                    or bbox[1] < BORDER_PX - 0.5
                    or bbox[2] > w - 0.5 - BORDER_PX
                    or bbox[3] > h - 0.5 - BORDER_PX
                )
            fraction = n_seen / n_full if n_full else 0.0
            truth.append(TargetTruth(tg.target_id, tg.cls, bbox, round(fraction, 4), cut))
        img *= np.float32(self.gain(t_s))
        if self.look.noise_sigma > 0:
            noise = self._rng.standard_normal(img.shape, dtype=np.float32)
            img += noise * np.float32(self.look.noise_sigma)
        out = np.clip(img + 0.5, 0, 255).astype(np.uint8)
        return out, truth

    def frames(self, times_s: Sequence[float]) -> Iterator[tuple[float, np.ndarray, list]]:
        """``(t_s, image, truth)`` for each scenario time in ``times_s``."""
        for t in times_s:
            image, truth = self.render(float(t))
            yield float(t), image, truth
