"""Stream messages are encoded once: the stored text and the published text agree with
encoding the message itself (``dumps_json``), bit for bit."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.tracking.types import Detection
from demtrack.server.hub import Hub, StreamMessage, encoded
from demtrack.server.store.codec import dumps_json, published_text
from demtrack.server.store.database import Store

_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**53), 2**53),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=8),
)
_values = st.recursive(
    _scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)
_payloads = st.dictionaries(
    st.text(max_size=6).filter(lambda k: k != "seq"), _values, max_size=5
).map(lambda d: {"type": "event", **d})


@settings(max_examples=200, deadline=None)
@given(_payloads, st.integers(0, 2**40))
def test_published_text_is_the_encoding_of_the_payload_with_its_seq(
    payload: dict[str, Any], seq: int
) -> None:
    text = published_text(dumps_json(payload), seq)
    assert text == dumps_json({**payload, "seq": seq})
    assert json.loads(text) == {**payload, "seq": seq}


def _fix_body(det_id: int) -> dict[str, Any]:
    return {
        "detection_id": det_id,
        "t_s": 1.25 * det_id,
        "sensor": "cam1",
        "hits": [{"e_m": 1.0 / 3.0, "n_m": -2.5e-7, "u_m": 300.125, "lat_deg": 40.3}],
        "road_hit": None,
        "tracked": True,
        "label": "é \u2603",
    }


def test_an_event_holding_a_stored_fix_body_is_the_encoding_of_the_whole_payload(
    tmp_path: Path,
) -> None:
    store = Store(tmp_path / "s.sqlite3")
    try:
        det = Detection(0.0, "cam1", (10.0, 10.0, 20.0, 40.0), "human")
        ids = store.insert_batch([det, det], {"n_records": 2, "accepted": 2}, None).detection_ids
        bodies = [_fix_body(i) for i in ids]
        fixes = [(b["detection_id"], b["t_s"], "cam1", "human", "fix", b) for b in bodies]
        other = _fix_body(3)  # equal-looking, not one of the stored bodies
        events = [
            ("fix", {"type": "fix", "fix": bodies[0]}),
            ("event", {"type": "event", "kind": "ingest", "t_s": 2.0, "text": "batch 1"}),
            ("fix", {"type": "fix", "fix": bodies[1], "extra": [bodies[0]]}),
            ("fix", {"type": "fix", "fix": other}),
        ]
        stored = store.write_derived(fixes, [], events)
        assert [s for s, _ in stored] == [1, 2, 3, 4]
        for (_, payload), (seq, text) in zip(events, stored, strict=True):
            assert text == dumps_json(payload)
            assert published_text(text, seq) == dumps_json({**payload, "seq": seq})
        # what a reconnecting client is sent from the event log: the same messages
        assert store.events_since(0) == [
            {**p, "seq": s} for (_, p), (s, _) in zip(events, stored, strict=True)
        ]
    finally:
        store.close()


def test_the_hub_queues_a_stream_message_text_as_it_is() -> None:
    payload = {"type": "event", "kind": "x", "t_s": 0.5, "text": "a"}
    text = published_text(dumps_json(payload), 7)
    msg = StreamMessage(payload, 7, text)
    assert dict(msg) == {**payload, "seq": 7} and list(msg)[-1] == "seq"
    assert encoded(msg) is text
    assert encoded({**payload, "seq": 7}) == text  # a plain dict is encoded

    async def run() -> list[tuple[int, str]]:
        hub = Hub(10)
        hub.bind(asyncio.get_running_loop())
        client = hub.register()
        hub.publish([msg])
        return [client.queue.get_nowait()]

    assert asyncio.run(run()) == [(7, text)]
