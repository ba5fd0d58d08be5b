"""The terrain model.

The cell grid, the DEM (per-cell mean, variance, count; holes filled from a coarse DEM), the
bilinear surface and its kernel, the min/max pyramid the ray caster walks, DEM tile import
(resampling methods, the largest rectangle inside a warped footprint), point clouds, the
TIN gridding of sparse clouds (``tin``) and a new site's terrain from a cloud alone
(``cloud_site``: CRS and units, anchor, DTM/DSM selection), and DEMs larger than memory as
tiled Cloud-Optimized GeoTIFFs with per-block min/max, read by window (``tiled_dem``,
``tiled_write``).
May import ``core.geo`` and ``core.errors``.
"""
