"""Geodesy and coordinate reference systems.

The site's local east-north-up frame anchored to WGS84 (exact through ECEF with pyproj), CRS
parsing and units, geoid models (the undulation N(lat, lon) of a site's vertical datum:
EGM96 or any PROJ grid evaluated per point, a constant, or none; :mod:`.geoid`), the grid
references the field uses (UTM and MGRS, :mod:`.grid_ref`), and warping rasters and point
clouds from any CRS into the site frame.
Imports only ``core.errors``; every other package may import it.
"""
