"""A site folder: the site model and its sensors, loaded and checked in one place.

Layout (all paths in ``site.json`` are relative to the folder and may not leave it)::

    site.json        manifest (format "demtrack.site", version 1)
    dem.tif          3-band DEM GeoTIFF in the site frame (Dem.write)
    ortho.tif        RGB orthophoto GeoTIFF on the same frame (optional)
    roads.geojson    road centre lines, lon/lat (optional)
    images/*.png     one still per sensor, what the operator clicks on (optional)

Manifest::

    {"format": "demtrack.site", "version": 1, "name": "...",
     "frame": {"lat_deg", "lon_deg", "h_m", "crs": "EPSG:4979"},
     "geoid_undulation_m": N,             # stated, h = H + N for orthometric inputs
     "dem": "dem.tif", "orthophoto": "ortho.tif", "roads": "roads.geojson",
     "sensors": [{"id": "cam1", "name": "...", "head": {PanTiltHead.to_dict()},
                  "pan_deg": p, "tilt_deg": t, "image": "images/cam1.png"}]}
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..camera.pantilt import PanTiltHead
from ..camera.pinhole import Camera
from ..errors import DemtrackError, SiteError, UnknownSensorError
from ..geo.geodesy import LocalFrame
from ..geolocation.geolocate import Geolocator
from ..geolocation.roads import RoadNetwork
from ..terrain.dem import Dem
from .road_io import read_roads_geojson

__all__ = [
    "MANIFEST",
    "SITE_FORMAT",
    "SITE_FORMAT_VERSION",
    "Sensor",
    "Site",
    "load_site",
    "site_manifest",
]

SITE_FORMAT = "demtrack.site"
SITE_FORMAT_VERSION = 1
MANIFEST = "site.json"


@dataclass(frozen=True, eq=False)
class Sensor:
    """A camera on a pan-tilt head at its current pan and tilt.

    ``roll_deg`` is the camera's bank about its optical axis (0 on a levelled head; a
    fixed camera calibrated from control points may have some), stored in ``site.json``
    only when non-zero.
    """

    id: str
    name: str
    head: PanTiltHead
    pan_deg: float
    tilt_deg: float
    image_path: Path | None = None
    roll_deg: float = 0.0

    @functools.cached_property
    def camera(self) -> Camera:
        """The camera at the current pan, tilt (and roll); built once (both immutable)."""
        if self.roll_deg == 0.0:
            return self.head.camera_at(self.pan_deg, self.tilt_deg)
        return Camera.from_azimuth_tilt_roll(
            self.head.intrinsics,
            self.head.position_enu,
            self.head.mount_yaw_deg + self.pan_deg,
            self.tilt_deg,
            self.roll_deg,
        )

    def to_dict(self, root: Path) -> dict[str, Any]:
        """Manifest entry; the image path is written relative to ``root``.

        Both are resolved first: a loaded site holds its image as an absolute path while
        ``root`` may be relative (``--site site``), and the two must still compare.
        """
        out: dict[str, Any] = {
            "id": self.id,
            "name": self.name,
            "head": self.head.to_dict(),
            "pan_deg": self.pan_deg,
            "tilt_deg": self.tilt_deg,
        }
        if self.roll_deg != 0.0:
            out["roll_deg"] = self.roll_deg
        if self.image_path is not None:
            out["image"] = self.image_path.resolve().relative_to(Path(root).resolve()).as_posix()
        return out


@dataclass(frozen=True, eq=False)
class Site:
    """A loaded site: frame, DEM, optional orthophoto and roads, and sensors."""

    root: Path
    name: str
    frame: LocalFrame
    dem: Dem
    sensors: dict[str, Sensor]
    roads: RoadNetwork | None = None
    orthophoto_path: Path | None = None
    geoid_undulation_m: float = 0.0

    def sensor(self, sensor_id: str) -> Sensor:
        """The sensor called ``sensor_id``.

        Raises
        ------
        UnknownSensorError
            If the site has none by that id (the message names the known ones).
        """
        try:
            return self.sensors[sensor_id]
        except KeyError:
            known = ", ".join(sorted(self.sensors)) or "none"
            msg = f"unknown sensor {sensor_id!r}; this site has: {known}"
            raise UnknownSensorError(msg) from None

    def geolocator(self, **kwargs: Any) -> Geolocator:
        """A :class:`Geolocator` on this site's DEM, frame and roads."""
        return Geolocator(self.dem, self.frame, self.roads, **kwargs)


def _inside(root: Path, rel: Any, key: str) -> Path:
    if not isinstance(rel, str) or not rel:
        raise SiteError(f"site.json: {key!r} must be a relative path")
    path = (root / rel).resolve()
    if not path.is_relative_to(root.resolve()):
        raise SiteError(f"site.json: {key!r} points outside the site folder: {rel}")
    if not path.is_file():
        raise SiteError(f"site.json: {key!r} file is missing: {rel}")
    return path


def _number(doc: Mapping[str, Any], key: str, where: str, default: float | None = None) -> float:
    value = doc.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SiteError(f"{where}: {key!r} must be a finite number, got {value!r}")
    return float(value)


def _sensor(root: Path, doc: Any, k: int) -> Sensor:
    if not isinstance(doc, Mapping):
        raise SiteError(f"site.json: sensor {k} must be an object")
    sid = doc.get("id")
    if not isinstance(sid, str) or not sid:
        raise SiteError(f"site.json: sensor {k} needs a non-empty string 'id'")
    where = f"site.json: sensor {sid!r}"
    try:
        head = PanTiltHead.from_dict(doc.get("head"))  # type: ignore[arg-type]  # checked there
    except DemtrackError as exc:
        raise SiteError(f"{where}: {exc}") from None
    image = doc.get("image")
    return Sensor(
        sid,
        str(doc.get("name", sid)),
        head,
        _number(doc, "pan_deg", where, 0.0),
        _number(doc, "tilt_deg", where, 0.0),
        _inside(root, image, f"sensors[{sid}].image") if image is not None else None,
        _number(doc, "roll_deg", where, 0.0),
    )


def load_site(root: str | Path) -> Site:
    """Load and check a site folder.

    Raises
    ------
    SiteError
        With a one-line message naming the missing or malformed part.
    """
    root = Path(root)
    manifest = root / MANIFEST
    if not root.is_dir():
        raise SiteError(f"site folder not found: {root}")
    if not manifest.is_file():
        raise SiteError(f"not a site folder (no {MANIFEST}): {root}")
    try:
        doc = json.loads(manifest.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SiteError(f"{manifest} is not valid JSON: {exc.msg} (line {exc.lineno})") from None
    if not isinstance(doc, dict) or doc.get("format") != SITE_FORMAT:
        raise SiteError(f"{manifest}: format must be {SITE_FORMAT!r}")
    if doc.get("version") != SITE_FORMAT_VERSION:
        raise SiteError(
            f"{manifest}: unsupported version {doc.get('version')!r}; "
            f"this demtrack reads version {SITE_FORMAT_VERSION}"
        )
    try:
        frame = LocalFrame.from_dict(doc.get("frame"))  # type: ignore[arg-type]  # checked there
    except DemtrackError as exc:
        raise SiteError(f"site.json: frame: {exc}") from None
    try:
        dem = Dem.read(_inside(root, doc.get("dem"), "dem"))
        roads_rel = doc.get("roads")
        roads = read_roads_geojson(_inside(root, roads_rel, "roads"), frame) if roads_rel else None
    except SiteError:
        raise
    except DemtrackError as exc:
        raise SiteError(f"site {root}: {exc}") from None
    ortho_rel = doc.get("orthophoto")
    ortho = _inside(root, ortho_rel, "orthophoto") if ortho_rel else None
    sensors_doc = doc.get("sensors", [])
    if not isinstance(sensors_doc, list):
        raise SiteError("site.json: 'sensors' must be a list")
    sensors: dict[str, Sensor] = {}
    for k, entry in enumerate(sensors_doc):
        sensor = _sensor(root, entry, k)
        if sensor.id in sensors:
            raise SiteError(f"site.json: sensor id {sensor.id!r} appears twice")
        sensors[sensor.id] = sensor
    return Site(
        root,
        str(doc.get("name", root.name)),
        frame,
        dem,
        sensors,
        roads,
        ortho,
        _number(doc, "geoid_undulation_m", "site.json", 0.0),
    )


def site_manifest(
    site_name: str,
    frame: LocalFrame,
    sensors: list[Sensor],
    root: Path,
    *,
    dem: str = "dem.tif",
    orthophoto: str | None = "ortho.tif",
    roads: str | None = "roads.geojson",
    geoid_undulation_m: float = 0.0,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Build the ``site.json`` document for a site written to ``root``."""
    doc: dict[str, Any] = {
        "format": SITE_FORMAT,
        "version": SITE_FORMAT_VERSION,
        "name": site_name,
        "frame": frame.to_dict(),
        "geoid_undulation_m": geoid_undulation_m,
        "dem": dem,
    }
    if orthophoto:
        doc["orthophoto"] = orthophoto
    if roads:
        doc["roads"] = roads
    doc["sensors"] = [s.to_dict(root) for s in sensors]
    doc.update(extra or {})
    return doc
