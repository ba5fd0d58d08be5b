"""``/ws``: the live stream (fixes, track updates, sensor status, events).

Connect with the operator token (``?token=`` or an ``Authorization`` header) and
optionally ``?since=N`` to be sent every stored message with ``seq > N`` before the live
ones, with ``&store=<id>`` (the ``store_id`` of the ``hello`` that ``N`` came from): a
``since`` of another store (the server restarted on a fresh database) or beyond the
newest message is not resumed, ``hello.start_over`` says so and the client is sent what
comes after the newest message. A bad ``since`` (not an integer from 0 to 2^63 - 1) or
``batch`` is answered with an ``error`` message, then a close (1008) with the same
reason. With ``?batch=1`` the client is sent several stream messages per frame
(``batch`` messages) whenever more than one is waiting, live or replayed; without it (or
with ``batch=0``), one message per frame. Messages are described in
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
from ..messages import (
    MAX_SEQ,
    ErrorMessage,
    HelloMessage,
    PongMessage,
    ResumeMessage,
    client_adapter,
)
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
    """Send stored messages with ``seq > since`` (the sender then skips older live ones).

    ``since`` at most the newest stored message (the callers check): a larger one would
    make the sender skip every live message up to it.
    """
    async with client.send_lock:
        after = since
        while True:
            rows = await run_in_threadpool(state.store.events_since, after, _PAGE)
            if rows:
                await _send_all(ws, state.hub, client, [dumps_json(m) for m in rows])
                after = rows[-1]["seq"]
            if len(rows) < _PAGE:
                break
        client.last_sent = after


async def _resume(ws: WebSocket, state: ConsoleState, client: Client, since: int) -> None:
    """Answer a ``resume``: the stored messages after ``since``.

    Beyond the newest: a ``hello`` that starts the client over, then live messages.
    """
    last = await run_in_threadpool(state.store.last_seq)
    if since > last:
        await _hello(ws, state, client, since, True, last)
    else:
        await _replay(ws, state, client, since)


async def _hello(
    ws: WebSocket,
    state: ConsoleState,
    client: Client,
    since: int | None,
    start_over: bool,
    last: int | None = None,
) -> None:
    """Send ``hello``; then the stored messages after ``since``, or none (live from now)."""
    if last is None:
        last = await run_in_threadpool(state.store.last_seq)
    start_over = start_over or (since is not None and since > last)
    hello = HelloMessage(
        last_seq=last, since=since, store_id=state.store.store_id, start_over=start_over
    )
    async with client.send_lock:
        await _send(ws, hello.model_dump_json())
    if since is not None and not start_over:
        await _replay(ws, state, client, since)
    else:
        client.last_sent = last


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
                    await _resume(ws, state, client, parsed.since)
                    continue
                reply = PongMessage(nonce=parsed.nonce).model_dump_json()
        async with client.send_lock:
            await _send(ws, reply)


def _since(text: str | None) -> tuple[int | None, str | None]:
    """``?since=``'s value, or the one-line problem with it."""
    if text is None:
        return None, None
    problem = f"since must be an integer from 0 to {MAX_SEQ} (a stream sequence number)"
    if not text.isascii() or not text.isdigit() or len(text) > 19 or int(text) > MAX_SEQ:
        shown = text if len(text) <= 24 else f"{text[:20]}... ({len(text)} characters)"
        return None, f"{problem}, got {shown!r}"
    return int(text), None


@router.websocket("/ws")
async def stream(ws: WebSocket) -> None:
    """The live stream; see the module docstring."""
    state: ConsoleState = ws.app.state.console
    if not token_ok(ws):
        await ws.close(code=1008, reason="operator token required")
        return
    since, problem = _since(ws.query_params.get("since"))
    batch = _BATCH.get(ws.query_params.get("batch", "0").lower())
    if problem is None and batch is None:
        problem = "batch must be 0 or 1"
    await ws.accept()  # refusals are told in an error message, then the close reason
    if problem is not None:
        await _send(ws, _error(problem))
        # a close reason holds at most 123 bytes; the error message has it all
        await ws.close(code=1008, reason=problem.encode()[:120].decode(errors="ignore"))
        return
    store = ws.query_params.get("store")
    client = state.hub.register(batch=bool(batch))
    tasks: list[asyncio.Task] = []
    try:
        await _hello(ws, state, client, since, store is not None and store != state.store.store_id)
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
