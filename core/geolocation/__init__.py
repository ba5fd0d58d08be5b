"""Geolocation.

A pixel becomes a viewing ray and every terrain hit along it (rules first, last, all, road),
with first-order uncertainty; the road network and the paper's road rule; the fix builder
that turns detections into tracker fixes, at the pose of each detection's moment for moving
heads (``posed_rays``), and the pose-latency estimate (``pose_latency``). May import
``core.camera``, ``core.raycast``, ``core.terrain``, ``core.geo``, ``core.tracking.types``
and ``core.errors``.
"""
