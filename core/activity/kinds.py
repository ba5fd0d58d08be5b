"""The one list of event kinds: what the activity detectors, the tracker and ingest report.

Every event the server stores in its ``activity`` table or streams as an ``event``
message has one of these kinds. :class:`EventKind` is a :class:`~enum.StrEnum`: a member
equals, hashes, formats and encodes (JSON) as its plain string value, so stored bodies
and stream messages hold exactly the strings they always held.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["ACTIVITY_KINDS", "INTERVAL_KINDS", "EventKind"]


class EventKind(StrEnum):
    """Kinds of events, in the order the console lists them."""

    LOITERING = "loitering"
    RENDEZVOUS = "rendezvous"
    CONVOY = "convoy"
    ZONE_ENTER = "zone-enter"
    ZONE_LEAVE = "zone-leave"
    HANDOFF = "handoff"
    TRACK_CONFIRMED = "track_confirmed"
    TRACK_ENDED = "track_ended"
    #: A log line per ingested batch (a stream message only: never an activity row).
    INGEST = "ingest"


#: Kinds that last a while (deduplicated as episodes with a start and an end).
INTERVAL_KINDS: tuple[EventKind, ...] = (
    EventKind.LOITERING,
    EventKind.RENDEZVOUS,
    EventKind.CONVOY,
)
#: Kinds of the ``activity`` table (every kind but ``ingest``).
ACTIVITY_KINDS: tuple[EventKind, ...] = tuple(k for k in EventKind if k is not EventKind.INGEST)
