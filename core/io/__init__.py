"""Exchange formats.

Detection records (CSV, JSON Lines) with per-record errors, pose telemetry files
(``pose_io``), track exports with one writer per format (GeoJSON, CSV, GPX, KML/KMZ,
GeoPackage: ``track_io`` and the ``export_*`` modules) and GeoJSON reading. May import
``core.tracking.types``, ``core.camera.pose_series``, ``core.geo`` and ``core.errors``.
"""
