"""The event-log follower: woken by the store's NOTIFY, every message once, in order."""

from __future__ import annotations

import threading
import time
from typing import Any

from demtrack.server.cluster.event_tail import EventTail
from demtrack.server.store.opening import open_store


def _event(k: int) -> tuple[str, dict[str, Any]]:
    return "event", {"type": "event", "kind": "ingest", "t_s": float(k), "text": f"m{k}"}


def test_messages_of_two_writers_arrive_once_in_order_on_notify(postgres_url: str) -> None:
    a, b = open_store(postgres_url), open_store(postgres_url)
    got: list[dict[str, Any]] = []
    lock = threading.Lock()

    def publish(messages: list[dict[str, Any]]) -> None:
        with lock:
            got.extend(messages)

    # poll_s far beyond the test: only the notifications wake it
    tail = EventTail(postgres_url, a.events_since, publish, a.last_seq(), poll_s=3600).start()
    try:
        writers = [
            threading.Thread(
                target=lambda s=s, o=o: [
                    s.write_derived([], [], [_event(o + k)]) for k in range(20)
                ]
            )
            for s, o in ((a, 0), (b, 100))
        ]
        for w in writers:
            w.start()
        for w in writers:
            w.join()
        deadline = time.monotonic() + 60
        while len(got) < 40 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        tail.stop()
    assert [m["seq"] for m in got] == list(range(1, 41))
    assert got == a.events_since(0, 100)
    texts = [m["text"] for m in got]
    assert sorted(texts) == sorted(f"m{k}" for k in [*range(20), *range(100, 120)])
    for offset in (0, 100):  # each writer's own messages in its order
        mine = [t for t in texts if int(t[1:]) // 100 == offset // 100]
        assert mine == [f"m{offset + k}" for k in range(20)]
    a.close()
    b.close()


def _log(seqs: list[int]):
    def events_since(after: int, limit: int) -> list[dict[str, Any]]:
        return [{"seq": s} for s in sorted(seqs) if s > after][:limit]

    return events_since


def test_a_hole_holds_the_messages_after_it_until_it_fills() -> None:
    seqs = [1, 2, 4, 5]
    got: list[int] = []
    tail = EventTail("unused", _log(seqs), lambda ms: got.extend(m["seq"] for m in ms), 0)
    tail.gap_wait_s = 3600.0
    assert tail.drain() == 2 and got == [1, 2]
    assert tail.drain() == 0  # 3 still missing
    seqs.append(3)
    assert tail.drain() == 3 and got == [1, 2, 3, 4, 5]
    assert tail.n_skipped == 0


def test_a_hole_that_never_fills_is_passed_after_the_wait() -> None:
    got: list[int] = []
    tail = EventTail("unused", _log([1, 3, 4]), lambda ms: got.extend(m["seq"] for m in ms), 0)
    tail.gap_wait_s = 0.0
    tail.drain()
    assert got == [1, 3, 4]
    assert tail.n_skipped == 1


def test_pages_of_the_log_are_all_published() -> None:
    got: list[int] = []
    n = 2500  # more than one page of events_since
    tail = EventTail(
        "unused", _log(list(range(1, n + 1))), lambda ms: got.extend(m["seq"] for m in ms), 0
    )
    assert tail.drain() == n
    assert got == list(range(1, n + 1))
