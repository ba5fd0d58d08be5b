"""Video in the console: the newest frame of each camera, its endpoints, the video replay.

:mod:`.jpeg` checks and makes JPEG frames; :mod:`.frame_book` keeps the newest frame of
each sensor (bounded memory: one JPEG per sensor, its UTC time and the boxes of that
frame when known); :mod:`.frames_http` is the logic of ``PUT /api/sensors/{id}/frame`` and
``GET /api/sensors/{id}/frame.jpg`` (the router is :mod:`demtrack.server.api.video`);
:mod:`.source` is what a video replay needs from its caller (rendered or recorded videos
of the replayed scenarios); :mod:`.replay_video` decodes those videos in the replay's
clock, runs the video detector (:mod:`demtrack.core.video`) and feeds the detections to
the pipeline and the frames to the book (:mod:`.frame_keeper` finds the frame a lagging
detection belongs to); :mod:`.service` starts it from the settings. May import ``core``
and the server's ingest, settings and store layers; the API imports it, nothing below
does.
"""
