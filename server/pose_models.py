"""Pydantic models of the pose endpoints (``/api/sensors/{id}/poses``) and of a current pose."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["PoseAckOut", "PoseBatchIn", "PoseOut"]


class PoseBatchIn(BaseModel):
    """A batch of one sensor's pose samples.

    Each record is ``{"t": UNIX s (or ISO 8601 with a zone), "pan_deg", "tilt_deg",
    "hfov_deg"?, "roll_deg"?, "e_m", "n_m", "u_m"?, "yaw_deg", "pitch_deg",
    "platform_roll_deg"?}`` (``"time"`` may stand for ``t``). Pan clockwise from the
    mount's zero, tilt up from level, hfov the lens's horizontal field of view (all
    degrees); a moving platform adds its position (site-frame ENU metres; ``u_m``
    defaults to the surveyed height) and attitude (yaw clockwise from true north, pitch
    nose up, roll right wing down). Records are checked one by one; bad ones (not
    finite, not newer than the sensor's newest stored pose, other optional fields than
    its series) are skipped and counted by reason.
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=True)

    batch_key: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        description="client's id for the batch: a resent batch with a key already stored"
        " is acknowledged again and not stored twice",
    )
    poses: list[Any] = Field(description="pose records (see above)")


class PoseAckOut(BaseModel):
    """Sent only after the batch's transaction has committed."""

    model_config = ConfigDict(extra="allow")

    batch_id: int
    sensor: str
    n_records: int
    accepted: int
    skipped: int
    counts: dict[str, int]
    issues: list[dict[str, Any]]
    duplicate: bool


class PoseOut(BaseModel):
    """A sensor's current pose (its newest stored sample)."""

    model_config = ConfigDict(extra="allow")

    t_s: float = Field(description="UNIX seconds, UTC")
    time_utc: str = Field(description="t_s as ISO 8601 UTC with Z")
    pan_deg: float
    tilt_deg: float
    roll_deg: float
    hfov_deg: float | None = Field(description="horizontal field of view; null: calibrated lens")
    position_enu: list[float] | None = None
    platform_ypr_deg: list[float] | None = None
