"""Server settings: one pydantic-settings object, environment prefix ``DEMTRACK_``.

Built by :func:`demtrack.server.app.create_app` (never at import time) from keyword
arguments, then the environment (``DEMTRACK_SITE``, ``DEMTRACK_TOKEN``, ...), then a
``.env`` file in the working directory.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from demtrack.core.io.times import parse_time_value

from .cot.target import parse_cot_url

__all__ = ["Settings"]


class Settings(BaseSettings):
    """Everything the console server can be told.

    Attributes
    ----------
    site : Path
        The site folder (``site.json`` inside).
    db_path : Path or None
        SQLite file; default ``<site>/console.sqlite3`` (next to the site's files).
    database_url : str or None
        ``postgresql://user[:password]@host[:port]/database`` (``DEMTRACK_DATABASE_URL``):
        keep the store on that PostgreSQL + PostGIS server instead of the SQLite file (see
        docs/postgres.md); unset (the default): SQLite, ``db_path``.
    token : SecretStr or None
        Operator token. When unset, one is generated on first start, stored in
        ``<db_path>.token`` (mode 0600) and reused on later starts.
    open_reads : bool
        Serve the read-only endpoints without the token (writes and the WebSocket
        always need it).
    cors_origins : list of str
        Origins allowed by CORS; empty (the default) sends no CORS headers at all.
    max_body_bytes : int
        Largest request body accepted (413 beyond it).
    max_ws_message_bytes : int
        Largest client WebSocket message handled (an error message beyond it).
    ws_queue_size : int
        Messages buffered per WebSocket client; a client that falls this far behind is
        disconnected (code 1013) and may resume with ``?since=N``.
    ws_compression : bool
        Offer permessage-deflate on WebSockets. Off by default: the hub sends one text to
        every client, and deflate compresses it once per client (on the replay soak it
        was 3 % of the server's time with one client); turn it on for operators on slow
        links.
    max_batch : int
        Most detection records per ingest request.
    tracker_method : str
        A method of :data:`demtrack.core.tracking.METHODS`.
    warm_up : bool
        Compile (or load) the numba kernels at start-up.
    replay : list of str
        Scenarios replayed live into the ingest path (``DEMTRACK_REPLAY=
        vehicle-run,pedestrians``); empty for none. They are made by the scenario source
        handed to :func:`~demtrack.server.app.create_app`, which checks the names against
        it (the sample site's needs a generated sample site).
    replay_speed : float
        Replay speed, times real time.
    replay_loop : bool
        Repeat the scenarios forever (else play them once).
    replay_copies : int
        Copies of each replayed scenario, staggered over its period, each with its own
        noise seed (a busier scene: 4 copies of all three keep about 20 tracks alive).
    replay_rate_hz : float
        The replayed cameras' frame rate (Hz).
    replay_duration_s : float
        Stop the replay after this much scenario time (s); 0 for no end.
    replay_start_s : float or None
        UTC time of the replay's start (UNIX seconds; ``DEMTRACK_REPLAY_START_S`` also
        takes ISO 8601 with a zone, or ``now``): the replayed detections carry real times
        from it (never before the store's newest time). None (the default): scenario
        time, from 0 on a fresh store.
    replay_batch_s : float
        The replay sends the frames that fell due at most this often (wall seconds), as a
        camera gateway buffering that long would; 0 sends each frame as soon as it is due.
        A batch's cost is largely fixed, so at 10x the default cuts the server's CPU per
        detection by about a third (see docs/benchmarks.md).
    scene3d : bool
        Serve the viser 3D scene on its own port.
    viser_host : str
        Address the 3D scene binds (the CLI passes the API's ``--host``).
    viser_port : int
        Port of the 3D scene (0 = any free; viser moves off a busy port silently).
    scene3d_rays : int
        Viewing rays kept in the 3D scene (the newest).
    reorder_lag_s : float
        Fixes wait this long (scenario time, behind the newest fix) in a reorder buffer so
        slightly out-of-order batches from several cameras are tracked in time order; a
        fix older than what was already tracked is stored with ``tracked: false``.
    pose_message_interval_s : float
        Least wall-clock time between two ``sensor_pose`` stream messages of one sensor
        (s; the newest pose always goes out, at the end of the interval at worst).
    track_retain_s : float
        The live tracker forgets a track that ended more than this long ago (scenario
        time; it stays in SQLite and the API). At least the re-acquisition window (30 s)
        and, with live events, ``events_window_s`` are kept whatever this says.
    events : bool
        Run the activity detectors and hand-off prediction on the live tracks.
    events_every_s, events_window_s, events_sample_s : float
        Re-evaluate every this much scenario time, over this sliding window, on track
        points this far apart.
    loiter_radius_m, loiter_min_s : float
        Loitering: inside a disc of this radius for at least this long.
    rendezvous_distance_m, rendezvous_stop_mps, rendezvous_min_s : float
        Rendezvous: this close, both slower than this, for at least this long.
    convoy_path_tolerance_m, convoy_min_distance_m, convoy_max_lag_s : float
        Convoy: on the leader's path within the tolerance, a steady lag up to the
        maximum, for at least the distance.
    zones_path : Path or None
        GeoJSON zones (lon/lat polygons, ``properties.name``) for enter/leave events;
        default ``<site>/zones.geojson`` when that file exists.
    handoff_horizon_s, handoff_dt_s : float
        Hand-off prediction horizon and time step (0 horizon: no prediction).
    cot_url : str or None
        Send the live tracks and the markers as Cursor-on-Target events to a TAK peer:
        ``udp://239.2.3.1:6969`` (multicast, ``?ttl=N`` and ``&iface=ADDR`` optional),
        ``udp://host:port`` or ``tcp://takserver:8087``; unset for none.
    cot_stale_s : float
        A track's CoT event goes stale this long after its position's time (s).
    cot_marker_stale_s : float
        A marker's CoT event goes stale this long after it is sent (s).
    cot_queue_size : int
        Batches of stream messages the CoT sender buffers; beyond, they are dropped
        (ingest never waits for the network).
    heads : {"auto", "sim", "off"}
        Pan-tilt-zoom heads of the site's active sensors. ``auto`` (the default) drives the
        heads ``site.json`` gives a ``head_adapter`` (ONVIF, or an explicit simulated one)
        and leaves the others to their gateways (their poses come from the API: a simulated
        head would invent poses for them); ``sim`` also simulates a head for every active
        sensor without an adapter entry; ``off`` drives none.
    heads_period_s : float
        The head controller's tick (s): status polls, pose feed, follow commands.
    max_frame_bytes : int
        Largest JPEG frame ``PUT /api/sensors/{id}/frame`` keeps (422 beyond it).
    replay_video : bool
        The replay's detections come from the video detector run on each camera's video
        of the scenario (the scenario source renders or reads them, see
        :mod:`demtrack.server.video.replay_video`), and its frames go to the frame book.
    replay_frame_hz : float
        Video replay: most frames per second (wall clock) put in the frame book per camera;
        at higher replay speeds the panel skips frames, the detector does not.
    lease_ttl_s : float
        On PostgreSQL with several server processes: how long the tracker's site lease
        lasts unless renewed (renewed every third of it); a process that dies is
        replaced as the site's tracker this long after (:mod:`demtrack.server.cluster`).
    """

    model_config = SettingsConfigDict(
        env_prefix="DEMTRACK_", env_file=".env", extra="ignore", validate_default=True
    )

    site: Path
    db_path: Path | None = None
    database_url: str | None = None
    token: SecretStr | None = None
    open_reads: bool = False
    cors_origins: list[str] = Field(default_factory=list)
    max_body_bytes: int = Field(default=4 * 1024 * 1024, gt=0)
    max_ws_message_bytes: int = Field(default=64 * 1024, gt=0)
    ws_queue_size: int = Field(default=4096, gt=0)
    ws_compression: bool = False
    max_batch: int = Field(default=10_000, gt=0)
    tracker_method: str = "kalman"
    warm_up: bool = True
    replay: Annotated[list[str], NoDecode] = Field(default_factory=list)
    replay_speed: float = Field(default=1.0, gt=0, allow_inf_nan=False)
    replay_loop: bool = True
    replay_copies: int = Field(default=1, ge=1, le=100)
    replay_rate_hz: float = Field(default=10.0, gt=0, le=100, allow_inf_nan=False)
    replay_duration_s: float = Field(default=0.0, ge=0, allow_inf_nan=False)
    replay_batch_s: float = Field(default=0.1, ge=0, le=10, allow_inf_nan=False)
    replay_start_s: float | None = Field(default=None, ge=0, allow_inf_nan=False)
    scene3d: bool = False
    viser_host: str = "127.0.0.1"
    viser_port: int = Field(default=8080, ge=0, le=65535)
    scene3d_rays: int = Field(default=40, ge=1, le=1000)
    reorder_lag_s: float = Field(default=0.5, ge=0, le=60, allow_inf_nan=False)
    pose_message_interval_s: float = Field(default=0.2, ge=0, le=60, allow_inf_nan=False)
    track_retain_s: float = Field(default=600.0, ge=0, allow_inf_nan=False)
    events: bool = True
    events_every_s: float = Field(default=1.0, gt=0, le=3600, allow_inf_nan=False)
    events_window_s: float = Field(default=180.0, gt=0, le=86400, allow_inf_nan=False)
    events_sample_s: float = Field(default=0.5, gt=0, le=60, allow_inf_nan=False)
    loiter_radius_m: float = Field(default=10.0, gt=0, allow_inf_nan=False)
    loiter_min_s: float = Field(default=60.0, gt=0, allow_inf_nan=False)
    rendezvous_distance_m: float = Field(default=5.0, gt=0, allow_inf_nan=False)
    rendezvous_stop_mps: float = Field(default=0.5, gt=0, allow_inf_nan=False)
    rendezvous_min_s: float = Field(default=20.0, gt=0, allow_inf_nan=False)
    convoy_path_tolerance_m: float = Field(default=5.0, gt=0, allow_inf_nan=False)
    convoy_min_distance_m: float = Field(default=100.0, gt=0, allow_inf_nan=False)
    convoy_max_lag_s: float = Field(default=30.0, gt=0, allow_inf_nan=False)
    zones_path: Path | None = None
    handoff_horizon_s: float = Field(default=10.0, ge=0, le=120, allow_inf_nan=False)
    handoff_dt_s: float = Field(default=1.0, gt=0, le=10, allow_inf_nan=False)
    cot_url: str | None = None
    cot_stale_s: float = Field(default=60.0, gt=0, le=86_400, allow_inf_nan=False)
    cot_marker_stale_s: float = Field(default=86_400.0, gt=0, le=31_536_000, allow_inf_nan=False)
    cot_queue_size: int = Field(default=1000, gt=0, le=1_000_000)
    heads: Literal["auto", "sim", "off"] = "auto"
    heads_period_s: float = Field(default=0.1, gt=0, le=10, allow_inf_nan=False)
    max_frame_bytes: int = Field(default=2 * 1024 * 1024, gt=0)
    replay_video: bool = False
    replay_frame_hz: float = Field(default=5.0, gt=0, le=30, allow_inf_nan=False)
    lease_ttl_s: float = Field(default=5.0, ge=0.5, le=600, allow_inf_nan=False)

    @field_validator("replay_start_s", mode="before")
    @classmethod
    def _start_time(cls, value: Any) -> Any:
        """``now`` or ISO 8601 with a zone (the environment's forms) as UNIX seconds."""
        if isinstance(value, str) and value.strip():
            if value.strip().lower() == "now":
                return float(int(time.time()))
            return parse_time_value(value, "replay_start_s")
        return None if value == "" else value

    @field_validator("replay", mode="before")
    @classmethod
    def _split_replay(cls, value: Any) -> Any:
        """Accept ``"a,b"`` (the environment's form) as well as a list."""
        if isinstance(value, str):
            return [part.strip() for part in value.split(",") if part.strip()]
        return value

    @field_validator("cot_url")
    @classmethod
    def _check_cot_url(cls, value: str | None) -> str | None:
        """A URL the CoT sender can use (checked at start-up, not at the first event)."""
        if value is None or not value.strip():
            return None
        try:
            parse_cot_url(value)
        except ValueError as exc:  # SettingsError is a ValueError: pydantic reports it
            raise ValueError(str(exc)) from None
        return value.strip()

    @field_validator("database_url")
    @classmethod
    def _check_database_url(cls, value: str | None) -> str | None:
        """A ``postgresql://`` URL, or None (blank is None: SQLite)."""
        if value is None or not value.strip():
            return None
        if value.strip().split("://", 1)[0].lower() not in ("postgresql", "postgres"):
            raise ValueError("database_url must be a postgresql:// URL")
        return value.strip()

    @property
    def database_label(self) -> str:
        """The store as it may be printed: the SQLite file, or the URL without a password."""
        if self.database_url is None:
            return str(self.resolved_db_path)
        from .store.postgres.connection import safe_url

        return safe_url(self.database_url)

    @property
    def resolved_db_path(self) -> Path:
        """The SQLite file actually used."""
        return self.db_path if self.db_path is not None else self.site / "console.sqlite3"
