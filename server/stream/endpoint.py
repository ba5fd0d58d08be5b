"""``/ws``: the live stream (fixes, track updates, sensor status, events).

Connect with the operator token (``?token=`` or an ``Authorization`` header) and
optionally ``?since=N`` to be sent every stored message with ``seq > N`` before the live
ones. With ``?batch=1`` the client is sent several stream messages per frame (``batch``
messages) whenever more than one is waiting, live or replayed; without it (or with
``batch=0``), one message per frame. Messages are described in
:mod:`demtrack.server.messages`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from fastapi import APIRouter, WebSocket
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.websockets import WebSocketDisconnect

from ..hub import OVERFLOW, Client, Hub, pack, take
from ..messages import ErrorMessage, HelloMessage, PongMessage, ResumeMessage, client_adapter
from ..security import token_ok
from ..state import ConsoleState
from ..store.codec import dumps_json

__all__ = ["router"]

router = APIRouter(tags=["stream"])
log = logging.getLogger("demtrack.server")
_PAGE = 1000
_CLIENT = client_adapter()
_BATCH = {"1": True, "true": True, "0": False, "false": False}


async def _send(ws: WebSocket, text: str) -> None:
    await ws.send_text(text)


async def _send_all(ws: WebSocket, hub: Hub, client: Client, texts: list[str]) -> None:
    """Send encoded stream messages in order: batched for a client that opted in."""
    if client.batch and len(texts) > 1:
        texts = pack(texts, hub.batch_max_messages, hub.batch_max_chars)
    for text in texts:
        await _send(ws, text)


async def _replay(ws: WebSocket, state: ConsoleState, client: Client, since: int) -> None:
    """Send stored messages with ``seq > since`` (the sender then skips older live ones)."""
    async with client.send_lock:
        after = since
        while True:
            rows = await run_in_threadpool(state.store.events_since, after, _PAGE)
            if rows:
                await _send_all(ws, state.hub, client, [dumps_json(m) for m in rows])
                after = rows[-1]["seq"]
            if len(rows) < _PAGE:
                break
        client.last_sent = max(after, since)


async def _sender(ws: WebSocket, hub: Hub, client: Client) -> None:
    while True:
        item = await client.queue.get()
        if item == OVERFLOW:
            overflowed = True
            items: list[tuple[int, str]] = []
        elif client.batch:
            items, overflowed = take(client, item, hub.batch_max_messages, hub.batch_max_chars)
        else:
            items, overflowed = [item], False
        if items:
            async with client.send_lock:
                # a replay may have sent some already (resume while live)
                fresh = [text for seq, text in items if seq > client.last_sent]
                if fresh:
                    await _send_all(ws, hub, client, fresh)
                    client.last_sent = items[-1][0]
        if overflowed:
            await ws.close(code=1013, reason="client too slow; reconnect with ?since=N")
            return


def _error(message: str) -> str:
    return ErrorMessage(message=message).model_dump_json()


def _summary(exc: ValidationError) -> str:
    parts = []
    for e in exc.errors()[:3]:
        loc = ".".join(str(x) for x in e.get("loc", ()))
        parts.append(f"{loc}: {e.get('msg')}" if loc else str(e.get("msg")))
    return "; ".join(parts)


async def _receiver(ws: WebSocket, state: ConsoleState, client: Client) -> None:
    limit = state.settings.max_ws_message_bytes
    while True:
        msg = await ws.receive()
        if msg["type"] == "websocket.disconnect":
            return
        text = msg.get("text")
        if text is None:
            reply = _error("send JSON text messages, not binary")
        elif len(text.encode()) > limit:
            reply = _error(f"message of {len(text.encode())} bytes exceeds the {limit} byte limit")
        else:
            try:
                parsed = _CLIENT.validate_json(text)
            except ValidationError as exc:
                reply = _error(f"malformed message: {_summary(exc)}")
            else:
                if isinstance(parsed, ResumeMessage):
                    await _replay(ws, state, client, parsed.since)
                    continue
                reply = PongMessage(nonce=parsed.nonce).model_dump_json()
        async with client.send_lock:
            await _send(ws, reply)


@router.websocket("/ws")
async def stream(ws: WebSocket) -> None:
    """The live stream; see the module docstring."""
    state: ConsoleState = ws.app.state.console
    if not token_ok(ws):
        await ws.close(code=1008, reason="operator token required")
        return
    since_text = ws.query_params.get("since")
    since: int | None = None
    if since_text is not None:
        try:
            since = int(since_text)
            if since < 0:
                raise ValueError
        except ValueError:
            await ws.close(code=1008, reason="since must be a non-negative integer")
            return
    batch = _BATCH.get(ws.query_params.get("batch", "0").lower())
    if batch is None:
        await ws.close(code=1008, reason="batch must be 0 or 1")
        return
    await ws.accept()
    client = state.hub.register(batch=batch)
    tasks: list[asyncio.Task] = []
    try:
        last = await run_in_threadpool(state.store.last_seq)
        await _send(ws, HelloMessage(last_seq=last, since=since).model_dump_json())
        if since is not None:
            await _replay(ws, state, client, since)
        else:
            client.last_sent = last
        tasks = [
            asyncio.create_task(_sender(ws, state.hub, client)),
            asyncio.create_task(_receiver(ws, state, client)),
        ]
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for t in done:
            exc = t.exception()
            if exc is not None and not isinstance(exc, WebSocketDisconnect | RuntimeError):
                log.warning("websocket client failed: %r", exc)
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        state.hub.unregister(client)
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(BaseException):
                await t
