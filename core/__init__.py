"""Geolocation engine: geodesy, DEM, ray casting, cameras (no web imports)."""
