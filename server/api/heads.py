"""``/api/heads``, ``/api/sensors/{id}/head``, ``/slew``, ``/follow``: pan-tilt-zoom heads.

``PUT /slew`` points a head at a pan / tilt (/ field of view), or at a ground point
(``e_m``, ``n_m`` and optionally ``u_m``, site frame, m: the inverse problem, with the
sight line checked; 422 with the reason when the head cannot see it). ``PUT /follow``
assigns it a live track, ``DELETE /follow`` releases it, ``GET /head`` says what it
does and where it points (``GET /api/heads``: every active head). Writes need the
operator token. An unknown sensor is 404, a sensor on a fixed mount 409, a head that
does not answer 502.
"""

from __future__ import annotations

import math
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Request
from pydantic import BaseModel, ConfigDict, Field, model_validator
from starlette.concurrency import run_in_threadpool

from demtrack.core.io.times import format_utc

from ..heads.adapter import HeadAdapterError
from ..heads.controller import HeadController, HeadNotActiveError
from .deps import OPERATOR, READER, StateDep
from .errors import error_responses

__all__ = ["FollowIn", "HeadOut", "SlewIn", "router"]

router = APIRouter(tags=["heads"])

_Deg = Annotated[float, Field(allow_inf_nan=False, ge=-360.0, le=360.0)]
_M = Annotated[float, Field(allow_inf_nan=False, ge=-1e7, le=1e7)]


class SlewIn(BaseModel):
    """Where to point: ``pan_deg`` and ``tilt_deg`` (``hfov_deg`` optional), or a ground point."""

    model_config = ConfigDict(extra="forbid")

    pan_deg: _Deg | None = None
    tilt_deg: _Deg | None = None
    hfov_deg: Annotated[float, Field(allow_inf_nan=False, gt=0.0, lt=180.0)] | None = None
    e_m: _M | None = None
    n_m: _M | None = None
    u_m: _M | None = None

    @model_validator(mode="after")
    def _one_form(self) -> SlewIn:
        angles = self.pan_deg is not None or self.tilt_deg is not None
        point = self.e_m is not None or self.n_m is not None or self.u_m is not None
        if angles == point:
            raise ValueError("give either pan_deg and tilt_deg (hfov_deg optional) or e_m and n_m")
        if angles and (self.pan_deg is None or self.tilt_deg is None):
            raise ValueError("pan_deg and tilt_deg go together")
        if point and (self.e_m is None or self.n_m is None or self.hfov_deg is not None):
            raise ValueError("a ground point needs e_m and n_m (u_m optional, no hfov_deg)")
        return self


class FollowIn(BaseModel):
    """The live track a head should follow."""

    model_config = ConfigDict(extra="forbid")

    track_id: int = Field(ge=1, le=2**63 - 1)


class HeadStatusOut(BaseModel):
    """Where the head last said it points."""

    t_s: float
    time: str
    pan_deg: float
    tilt_deg: float
    hfov_deg: float
    moving: bool


class HeadOut(BaseModel):
    """A head: what it does (``mode``, ``target``), where it points, its limits."""

    sensor_id: str
    kind: str = Field(description="sim or onvif")
    mode: str = Field(description="idle, slew, look, follow or handoff")
    target: dict[str, Any]
    status: HeadStatusOut | None
    error: str | None
    latency_s: float
    limits: dict[str, float]


async def _controller(request: Request) -> HeadController | None:
    ctl: HeadController | None = getattr(request.app.state, "heads", None)
    return ctl


_Heads = Annotated[HeadController | None, Depends(_controller)]


def _out(info: dict[str, Any]) -> HeadOut:
    status = info["status"]
    if status is not None:
        t = status["t_s"]
        status = {**status, "time": format_utc(t) if math.isfinite(t) else ""}
    return HeadOut(**{**info, "status": status})


async def _call(
    state: Any, ctl: HeadController | None, sensor_id: str, fn: str, *args: Any
) -> HeadOut:
    state.site.sensor(sensor_id)  # 404 first, whatever runs the heads
    if ctl is None:
        raise HTTPException(
            409, f"sensor {sensor_id} is on a fixed mount, not an active pan-tilt-zoom head"
        )
    try:
        return _out(await run_in_threadpool(getattr(ctl, fn), sensor_id, *args))
    except HeadNotActiveError as exc:
        raise HTTPException(409, str(exc)) from None
    except HeadAdapterError as exc:
        raise HTTPException(502, str(exc)) from None


@router.get(
    "/api/heads",
    response_model=list[HeadOut],
    dependencies=READER,
    responses=error_responses(401),
    summary="Every active pan-tilt-zoom head",
)
async def list_heads(ctl: _Heads) -> list[HeadOut]:
    """The active heads (sensors on a fixed mount are not listed; none when heads are off)."""
    if ctl is None:
        return []
    return [_out(ctl.info(sid)) for sid in ctl.units]


@router.get(
    "/api/sensors/{sensor_id}/head",
    response_model=HeadOut,
    dependencies=READER,
    responses=error_responses(401, 404, 409),
    summary="A pan-tilt-zoom head's mode, target, status and limits",
)
async def get_head(sensor_id: str, state: StateDep, ctl: _Heads) -> HeadOut:
    """What the head does (idle, slew, look, follow, handoff) and where it points."""
    return await _call(state, ctl, sensor_id, "info")


@router.put(
    "/api/sensors/{sensor_id}/slew",
    response_model=HeadOut,
    dependencies=OPERATOR,
    responses=error_responses(401, 404, 409, 422, 502),
    summary="Point a head at a pan and tilt, or at a ground point",
)
async def slew(sensor_id: str, body: SlewIn, state: StateDep, ctl: _Heads) -> HeadOut:
    """Point the head; a ground point is checked for a clear sight line and the tilt range."""
    if body.e_m is not None and body.n_m is not None:
        return await _call(state, ctl, sensor_id, "look", body.e_m, body.n_m, body.u_m)
    return await _call(state, ctl, sensor_id, "slew", body.pan_deg, body.tilt_deg, body.hfov_deg)


@router.put(
    "/api/sensors/{sensor_id}/follow",
    response_model=HeadOut,
    dependencies=OPERATOR,
    responses=error_responses(401, 404, 409, 422, 502),
    summary="Assign a head to a live track",
)
async def follow(sensor_id: str, body: FollowIn, state: StateDep, ctl: _Heads) -> HeadOut:
    """The head aims at the track's predicted position each tick (404: no such live track)."""
    return await _call(state, ctl, sensor_id, "follow", body.track_id)


@router.delete(
    "/api/sensors/{sensor_id}/follow",
    response_model=HeadOut,
    dependencies=OPERATOR,
    responses=error_responses(401, 404, 409, 502),
    summary="Release a head",
)
async def release(sensor_id: str, state: StateDep, ctl: _Heads) -> HeadOut:
    """The head stops where it is and goes idle."""
    return await _call(state, ctl, sensor_id, "release")
