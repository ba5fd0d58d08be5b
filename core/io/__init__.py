"""Exchange formats.

Detection records (CSV, JSON Lines) with per-record errors, track exports (GeoJSON, CSV,
GPX, KML, GeoPackage) and GeoJSON reading. May import ``core.tracking.types``, ``core.geo``
and ``core.errors``.
"""
