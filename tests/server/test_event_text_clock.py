"""Stream log lines say clock times (issue 27): a hand-off at 14:32:05Z, not "at 3010.4 s"."""

from __future__ import annotations

from datetime import UTC, datetime

from demtrack.server.ingest.events import event_message

T_S = datetime(2026, 12, 1, 14, 32, 5, 400_000, tzinfo=UTC).timestamp()


def _handoff(exit_t_s):
    return {
        "kind": "handoff",
        "state": "start",
        "t_start_s": T_S - 7.0,
        "t_end_s": T_S,
        "track_ids": [4],
        "details": {"current": "cam1", "next_sensor": "cam3", "exit_t_s": exit_t_s},
    }


def test_handoff_text_says_the_utc_clock_time():
    msg = event_message(_handoff(T_S))
    assert msg.text == "track 4: cam1 loses it at 14:32:05Z, next cam3"
    assert msg.t_s == T_S - 7.0
    # rounded to the nearest second, as the oracle's datetime says
    late = event_message(_handoff(T_S + 0.2)).text
    assert late.endswith("loses it at 14:32:06Z, next cam3")
    assert event_message(_handoff(None)).text.endswith("loses it at an unknown time, next cam3")
