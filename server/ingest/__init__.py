"""Ingest -> durable store -> fixes -> online tracker -> stream messages.

:class:`~.pipeline.Pipeline` is the thin coordinator; each of its jobs has a module:

:mod:`.group_commit`     batches that arrive together commit in one transaction
:mod:`.reorder`          the reorder buffer (fixes handed over in time order)
:mod:`.fix_codec`        fix bodies <-> tracker fixes (one constructor, live and replay)
:mod:`.tracker_feed`     the online tracker, fed from the buffer; bounded memory
:mod:`.track_bodies`     track rows and ``track_update`` bodies, only what changed
:mod:`.events`           ``event`` messages: track confirmed / ended, activity, ingest
:mod:`.stream_messages`  the typed stream messages (msgspec structs, encoded once)
:mod:`.publish`          derived rows stored, then published as the stored text
:mod:`.replay_on_start`  the start-up replay of the stored fixes
:mod:`.pose_values`      posted pose records -> checked samples (the pose file reader)
:mod:`.pose_book`        stored poses, rolling series, detections waiting for their pose
:mod:`.pose_stream`      ``sensor_pose`` messages, rate-limited per sensor
:mod:`.poses`            :class:`~.poses.PoseIngest`, the server's pose entry (``state.poses``)

May import ``demtrack.core``, :mod:`demtrack.server.store`, :mod:`demtrack.server.hub`,
:mod:`demtrack.server.live_events` and :mod:`demtrack.server.footprints`; nothing here
imports the app or the routers.
"""

from __future__ import annotations

__all__: list[str] = []
