"""The site.

Its folder (``site.json``, DEM, orthophoto, cameras, roads, zones), loading and atomic
updates, road and zone files, orthophoto import, and synthetic camera views by ray casting.
May import every engine package below it (``geo``, ``terrain``, ``raycast``, ``camera``,
``geolocation``, ``io``) and ``core.errors``; none of those imports it.
"""
