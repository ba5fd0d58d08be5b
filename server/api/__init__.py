"""The HTTP API: one thin router per resource, and the error handlers.

A router parses the request (path, query, body models), calls one function of the layer
below (``server.site_info``, ``server.sensor_info``, ``server.pixel_geolocation``,
``server.listing``, ``server.track_query``, ``server.track_export``, ``server.synopsis``,
``server.visibility_service``, the pipeline, the 3D scene) and answers. Shared
dependency aliases live in :mod:`.deps`; engine exceptions become HTTP statuses in
:mod:`.errors` only. May import the rest of ``server`` and ``core``; nothing below
imports it (the live stream is :mod:`demtrack.server.stream`).
"""
