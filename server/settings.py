"""Server settings: one pydantic-settings object, environment prefix ``DEMTRACK_``.

Built by :func:`demtrack.server.app.create_app` (never at import time) from keyword
arguments, then the environment (``DEMTRACK_SITE``, ``DEMTRACK_TOKEN``, ...), then a
``.env`` file in the working directory.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings"]


class Settings(BaseSettings):
    """Everything the console server can be told.

    Attributes
    ----------
    site : Path
        The site folder (``site.json`` inside).
    db_path : Path or None
        SQLite file; default ``<site>/console.sqlite3`` (next to the site's files).
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
    max_batch : int
        Most detection records per ingest request.
    tracker_method : str
        A method of :data:`demtrack.core.tracking.METHODS`.
    warm_up : bool
        Compile (or load) the numba kernels at start-up.
    """

    model_config = SettingsConfigDict(
        env_prefix="DEMTRACK_", env_file=".env", extra="ignore", validate_default=True
    )

    site: Path
    db_path: Path | None = None
    token: SecretStr | None = None
    open_reads: bool = False
    cors_origins: list[str] = Field(default_factory=list)
    max_body_bytes: int = Field(default=4 * 1024 * 1024, gt=0)
    max_ws_message_bytes: int = Field(default=64 * 1024, gt=0)
    ws_queue_size: int = Field(default=1024, gt=0)
    max_batch: int = Field(default=10_000, gt=0)
    tracker_method: str = "kalman"
    warm_up: bool = True

    @property
    def resolved_db_path(self) -> Path:
        """The SQLite file actually used."""
        return self.db_path if self.db_path is not None else self.site / "console.sqlite3"
