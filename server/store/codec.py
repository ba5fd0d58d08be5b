"""The one JSON codec between the store and the stream.

Every stored body (fixes, tracks, activity, the event log) and every stream message is
encoded here, by one msgspec encoder, so the text the stream sends is the text the store
wrote: a message is encoded once, when it is stored, and published as that text
(:func:`published_text`). Stream messages may be dicts or the typed
:class:`msgspec.Struct` messages of :mod:`demtrack.server.ingest.stream_messages` (a
struct's tag first, then its fields in order: the same text as the dict with those keys).
A track's stored body is split into a head and one text per point
(:func:`split_track_body`) and joined back as the text of the whole
(:func:`track_body_text`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import msgspec

__all__ = [
    "dumps_json",
    "encode_json",
    "encode_reusing",
    "loads_json",
    "payload_dict",
    "published_text",
    "split_track_body",
    "track_body_text",
]

_ENCODER = msgspec.json.Encoder()
_DECODER = msgspec.json.Decoder()


def dumps_json(obj: Any) -> str:
    """Compact JSON: how every stored body and stream message is encoded.

    msgspec's encoder (about 9x faster than :func:`json.dumps` on fix and track bodies):
    the same text as ``json.dumps(obj, separators=(",", ":"))`` except that exponents
    carry no ``+`` (``1e21``) and NaN or infinities become ``null`` (JSON has neither;
    the server's numbers are finite by construction).
    """
    return encode_json(obj).decode()


def encode_json(obj: Any) -> bytes:
    """:func:`dumps_json`'s text as UTF-8 bytes (one msgspec encoder for the whole server)."""
    return _ENCODER.encode(obj)


def published_text(stored: str, seq: int) -> str:
    """The stream's text of a stored event payload: ``dumps_json({**payload, "seq": seq})``.

    The stored text is the payload's encoding (a JSON object without ``seq``); the key goes
    last, as the dict merge puts it, so the text is the same without encoding it again.
    """
    return f'{stored[:-1]},"seq":{int(seq)}}}' if stored != "{}" else f'{{"seq":{int(seq)}}}'


def encode_reusing(payload: Any, encoded: dict[int, tuple[Any, bytes]]) -> str:
    """``dumps_json(payload)``, reusing encodings of values already encoded.

    ``payload``: a dict or a :class:`msgspec.Struct`. ``encoded`` maps ``id(object) ->
    (object, its JSON)``; a payload value that is one of those objects (by identity) is
    inserted as that JSON, not encoded again.
    """
    if isinstance(payload, msgspec.Struct):
        fields = payload.__struct_fields__
        if any(id(getattr(payload, f)) in encoded for f in fields):
            payload = msgspec.structs.replace(
                payload,
                **{
                    f: msgspec.Raw(encoded[id(v)][1])
                    for f in fields
                    if id(v := getattr(payload, f)) in encoded
                },
            )
        return dumps_json(payload)
    if any(id(v) in encoded for v in payload.values()):
        payload = {
            k: msgspec.Raw(encoded[id(v)][1]) if id(v) in encoded else v for k, v in payload.items()
        }
    return dumps_json(payload)


def payload_dict(payload: Any) -> dict[str, Any]:
    """A stream message as a dict: a struct's tag (``type``) first, then its fields.

    A dict is returned as it is; a struct's field values are shared, not copied.
    """
    if not isinstance(payload, msgspec.Struct):
        return payload  # type: ignore[no-any-return]
    config = payload.__struct_config__
    out: dict[str, Any] = {}
    if config.tag_field is not None:
        out[config.tag_field] = config.tag
    for f in payload.__struct_fields__:
        out[f] = getattr(payload, f)
    return out


def loads_json(text: str | bytes) -> Any:
    """Parse a stored body (msgspec's decoder: the values :func:`json.loads` gives, ~3.5x faster).

    Stored track bodies are read back on every track, synopsis and export request; with
    :func:`json.loads` their decoding was the largest single cost of the console server
    under a live replay.
    """
    return _DECODER.decode(text)


def track_body_text(head: str, points: Sequence[str]) -> str:
    """A track's whole body as JSON: its stored head with ``points`` as the last key.

    The same text as encoding the whole body at once when ``points`` was its last key
    (as in every body the server writes).
    """
    sep = "," if head != "{}" else ""
    return f'{head[:-1]}{sep}"points":[{",".join(points)}]}}'


def split_track_body(row: Mapping[str, Any]) -> tuple[str, list[str], int]:
    """A track row's head text, point texts and the index its points start at.

    Rows either give the split form (``points_from`` and ``point_texts``: points from
    that index on, ``body`` without points) or a whole ``body`` (dict or JSON text).
    """
    body = row["body"]
    if "points_from" in row:
        head = body if isinstance(body, str) else dumps_json(body)
        return head, list(row["point_texts"]), int(row["points_from"])
    if isinstance(body, str):
        body = loads_json(body)
    head = dumps_json({k: v for k, v in body.items() if k != "points"})
    return head, [dumps_json(p) for p in body.get("points", ())], 0
