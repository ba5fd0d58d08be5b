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
     "vertical_datum": {"geoid": "EGM96"},  # the geoid of orthometric heights, below
     "geoid_undulation_m": N,             # N at the anchor (the constant, for old readers)
     "dem": "dem.tif", "orthophoto": "ortho.tif", "roads": "roads.geojson",
     "sensors": [{"id": "cam1", "name": "...", "head": {PanTiltHead.to_dict()},
                  "pan_deg": p, "tilt_deg": t, "image": "images/cam1.png"}]}

A site larger than memory adds ``"dem_tiled": "dem-tiled.tif"`` (a tiled DEM with block
min/max, ``demtrack dem tile``; ``core.terrain.tiled_dem``) and optionally
``"dem_memory_budget_mb"`` (1024): geolocation then casts against the tiled DEM through a
:class:`~demtrack.core.raycast.tiled_cast.TiledRayCaster` holding at most that much of it,
while ``dem`` (a coarser overview that fits, for the console) serves everything else.

A sensor entry may also carry, each written only when not its default:

* ``"roll_deg"`` (0): the camera's bank about its optical axis;
* ``"active"`` (false): a PTZ head whose pose comes from telemetry
  (:class:`~demtrack.core.camera.pose_series.PoseSeries`). A detection of an active
  sensor with no pose close enough in time is counted ``no_pose`` and never geolocated
  at the stored ``pan_deg`` / ``tilt_deg`` (those stay its resting pose, for display);
* ``"zoom_table"`` (none): the lens calibrated at several zooms,
  :meth:`~demtrack.core.camera.zoom_lens.ZoomTable.to_list` rows
  ``{"hfov_deg", "fx", "fy", "cx", "cy", "k1"?, "k2"?, "p1"?, "p2"?, "k3"?, "k4"?}``;
* ``"pose_latency_s"`` (0): how late the telemetry's stamps are relative to the frames
  (s; the pose of a frame at ``t`` is the series at ``t + pose_latency_s``);
* ``"max_pose_gap_s"`` (0.2): the farthest (s) a detection may be from its nearest pose
  sample to be geolocated;
* ``"slew_limits"`` (none): the head's slew limits, a mapping of names to finite numbers
  (e.g. ``{"pan_rate_deg_s": 60, "tilt_min_deg": -60}``), kept as given for the head
  simulator and adapters.

Vertical datum (``h = H + N(lat, lon)``; see :mod:`~demtrack.core.geo.geoid`)::

    {"geoid": "EGM96"}                       # PROJ's egm96_15.gtx, evaluated per point
    {"geoid": "grid", "grid": "geoid/g.tif", "name": "GEOID18"}  # a grid in the folder
    {"geoid": "constant", "undulation_m": -33.5}
    {"geoid": "none"}                        # ellipsoidal: no geoid model

A manifest without ``vertical_datum`` (older sites) keeps its meaning: a non-zero
``geoid_undulation_m`` is a constant model, 0 is none. A site that asks for a grid that is
not there does not load (:class:`~demtrack.core.errors.SiteError` naming the grid).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..camera.pantilt import PanTiltHead
from ..camera.pinhole import Camera
from ..camera.pose_series import DEFAULT_MAX_GAP_S
from ..camera.zoom_lens import ZoomTable
from ..errors import DemtrackError, SiteError, UnknownSensorError
from ..geo.geodesy import LocalFrame
from ..geo.geoid import EGM96_GRID, GeoidModel
from ..geolocation.geolocate import Geolocator
from ..geolocation.roads import RoadNetwork
from ..terrain.dem import Dem
from ..terrain.tiled_dem import TiledDem
from .road_io import read_roads_geojson

__all__ = [
    "MANIFEST",
    "SITE_FORMAT",
    "SITE_FORMAT_VERSION",
    "Sensor",
    "Site",
    "load_site",
    "site_manifest",
    "vertical_datum_doc",
]

SITE_FORMAT = "demtrack.site"
SITE_FORMAT_VERSION = 1
MANIFEST = "site.json"


@dataclass(frozen=True, eq=False)
class Sensor:
    """A camera on a pan-tilt head at its current pan and tilt.

    ``roll_deg`` is the camera's bank about its optical axis (0 on a levelled head; a
    fixed camera calibrated from control points may have some), stored in ``site.json``
    only when non-zero. ``active``, ``zoom``, ``pose_latency_s``, ``max_pose_gap_s`` and
    ``slew_limits`` describe a PTZ head whose pose comes from telemetry (the module
    notes); each is stored only when not its default.
    """

    id: str
    name: str
    head: PanTiltHead
    pan_deg: float
    tilt_deg: float
    image_path: Path | None = None
    roll_deg: float = 0.0
    active: bool = False
    zoom: ZoomTable | None = None
    pose_latency_s: float = 0.0
    max_pose_gap_s: float = DEFAULT_MAX_GAP_S
    slew_limits: Mapping[str, float] | None = None

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
        if self.active:
            out["active"] = True
        if self.zoom is not None:
            out["zoom_table"] = self.zoom.to_list()
        if self.pose_latency_s != 0.0:
            out["pose_latency_s"] = self.pose_latency_s
        if self.max_pose_gap_s != DEFAULT_MAX_GAP_S:
            out["max_pose_gap_s"] = self.max_pose_gap_s
        if self.slew_limits is not None:
            out["slew_limits"] = dict(self.slew_limits)
        if self.image_path is not None:
            out["image"] = self.image_path.resolve().relative_to(Path(root).resolve()).as_posix()
        return out


@dataclass(frozen=True, eq=False)
class Site:
    """A loaded site: frame, DEM, optional orthophoto and roads, and sensors.

    ``geoid`` is the site's vertical datum (the geoid of its orthometric heights, or
    ellipsoidal); ``geoid_undulation_m`` is that model's ``N`` (m) at the frame's anchor,
    for code that takes one constant.
    """

    root: Path
    name: str
    frame: LocalFrame
    dem: Dem
    sensors: dict[str, Sensor]
    roads: RoadNetwork | None = None
    orthophoto_path: Path | None = None
    geoid_undulation_m: float = 0.0
    geoid: GeoidModel = field(default_factory=GeoidModel.ellipsoidal)
    tiled_dem: TiledDem | None = None
    tiled_budget_bytes: int = 1 << 30

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
        """A :class:`Geolocator` on this site's DEM (the tiled one if any), frame and roads."""
        if self.tiled_dem is not None:
            kwargs.setdefault("memory_budget", self.tiled_budget_bytes)
            return Geolocator(self.tiled_dem, self.frame, self.roads, **kwargs)
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
    active = doc.get("active", False)
    if not isinstance(active, bool):
        raise SiteError(f"{where}: 'active' must be true or false, got {active!r}")
    zoom = None
    if doc.get("zoom_table") is not None:
        try:
            zoom = ZoomTable.from_list(doc["zoom_table"])
        except DemtrackError as exc:
            raise SiteError(f"{where}: zoom_table: {exc}") from None
    gap = _number(doc, "max_pose_gap_s", where, DEFAULT_MAX_GAP_S)
    if gap < 0.0:
        raise SiteError(f"{where}: 'max_pose_gap_s' must be >= 0 s, got {gap}")
    return Sensor(
        sid,
        str(doc.get("name", sid)),
        head,
        _number(doc, "pan_deg", where, 0.0),
        _number(doc, "tilt_deg", where, 0.0),
        _inside(root, image, f"sensors[{sid}].image") if image is not None else None,
        _number(doc, "roll_deg", where, 0.0),
        active,
        zoom,
        _number(doc, "pose_latency_s", where, 0.0),
        gap,
        _slew_limits(doc.get("slew_limits"), where),
    )


def _slew_limits(value: Any, where: str) -> dict[str, float] | None:
    """``slew_limits`` as given: a mapping of names to finite numbers (or None)."""
    if value is None:
        return None
    if not isinstance(value, Mapping):
        raise SiteError(f"{where}: 'slew_limits' must be an object of numbers")
    for key in value:
        if not isinstance(key, str):
            raise SiteError(f"{where}: slew_limits keys must be strings")
    return {key: _number(value, key, f"{where}: slew_limits") for key in value}


def vertical_datum_doc(geoid: GeoidModel, root: Path) -> dict[str, Any]:
    """The manifest's ``vertical_datum`` entry for ``geoid`` (a grid inside ``root``)."""
    if geoid.kind == "ellipsoidal":
        return {"geoid": "none"}
    if geoid.kind == "constant":
        return {"geoid": "constant", "undulation_m": geoid.n_m}
    if geoid.name == "EGM96" and geoid.grid_path is not None and geoid.grid_path.name == EGM96_GRID:
        return {"geoid": "EGM96"}
    grid = Path(geoid.grid_path)  # type: ignore[arg-type]  # a grid model has one
    try:
        rel = grid.resolve().relative_to(Path(root).resolve())
    except ValueError:
        raise SiteError(f"the geoid grid {grid} must be inside the site folder {root}") from None
    return {"geoid": "grid", "grid": rel.as_posix(), "name": geoid.name}


def _geoid(root: Path, doc: Mapping[str, Any]) -> GeoidModel:
    """The site's geoid model from ``vertical_datum`` (or the old constant N)."""
    vd = doc.get("vertical_datum")
    if vd is None:
        n = _number(doc, "geoid_undulation_m", "site.json", 0.0)
        return GeoidModel.constant(n) if n != 0.0 else GeoidModel.ellipsoidal()
    if not isinstance(vd, Mapping):
        raise SiteError(
            'site.json: \'vertical_datum\' must be an object such as {"geoid": "EGM96"}'
        )
    kind = vd.get("geoid")
    try:
        if kind == "none":
            return GeoidModel.ellipsoidal()
        if kind == "constant":
            return GeoidModel.constant(_number(vd, "undulation_m", "site.json: vertical_datum"))
        if isinstance(kind, str) and kind.upper() == "EGM96":
            return GeoidModel.egm96()
        if kind == "grid":
            path = _inside(root, vd.get("grid"), "vertical_datum.grid")
            name = vd.get("name")
            return GeoidModel.from_grid(path, name if isinstance(name, str) and name else None)
    except SiteError:
        raise
    except DemtrackError as exc:
        raise SiteError(f"site.json: vertical_datum: {exc}") from None
    raise SiteError(
        f"site.json: vertical_datum: 'geoid' must be EGM96, grid, constant or none, got {kind!r}"
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
        tiled_rel = doc.get("dem_tiled")
        tiled = TiledDem.open(_inside(root, tiled_rel, "dem_tiled")) if tiled_rel else None
        budget_mb = doc.get("dem_memory_budget_mb", 1024)
        if isinstance(budget_mb, bool) or not isinstance(budget_mb, int | float) or budget_mb <= 0:
            raise SiteError(
                f"site.json: 'dem_memory_budget_mb' must be a positive number, got {budget_mb!r}"
            )
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
    geoid = _geoid(root, doc)
    try:
        n_anchor = float(geoid.undulation_m(frame.lat_deg, frame.lon_deg))
    except DemtrackError as exc:
        raise SiteError(f"site.json: vertical_datum: {exc}") from None
    return Site(
        root,
        str(doc.get("name", root.name)),
        frame,
        dem,
        sensors,
        roads,
        ortho,
        n_anchor,
        geoid,
        tiled,
        int(budget_mb * 2**20),
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
    geoid: GeoidModel | None = None,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Build the ``site.json`` document for a site written to ``root``.

    With ``geoid`` the manifest states its ``vertical_datum`` and ``geoid_undulation_m``
    is that model's ``N`` at the anchor (rounded to 1 mm); without it only the constant
    ``geoid_undulation_m`` is written (the old form).
    """
    doc: dict[str, Any] = {
        "format": SITE_FORMAT,
        "version": SITE_FORMAT_VERSION,
        "name": site_name,
        "frame": frame.to_dict(),
    }
    if geoid is not None:
        doc["vertical_datum"] = vertical_datum_doc(geoid, root)
        n_anchor = geoid.undulation_m(frame.lat_deg, frame.lon_deg)
        geoid_undulation_m = round(float(n_anchor), 3)
    doc["geoid_undulation_m"] = geoid_undulation_m
    doc["dem"] = dem
    if orthophoto:
        doc["orthophoto"] = orthophoto
    if roads:
        doc["roads"] = roads
    doc["sensors"] = [s.to_dict(root) for s in sensors]
    doc.update(extra or {})
    return doc
