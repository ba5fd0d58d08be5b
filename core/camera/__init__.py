"""Cameras.

The OpenCV pinhole and lens-distortion model (pixel to ray, point to pixel), pan-tilt heads
and their landmark yaw calibration, poses that change over time (``pose_series``, zoom
lenses in ``zoom_lens``, pointing a head at a point in ``pointing``), camera poses surveyed
in projected CRSs, and camera fits to ground control points. May import ``core.raycast``,
``core.terrain``, ``core.geo`` and ``core.errors``.
"""
