"""Video in: reading video, detecting and classifying moving objects, MISB ST 0601 KLV.

Owns the video reader (PyAV: files and rtsp/udp/http streams, each frame timed from its
own presentation timestamp in UTC), the motion detectors (the VSAM hybrid of an adaptive
background model with three-frame differencing after Lipton et al. 1998 and Collins et
al. 2000, OpenCV's MOG2 and KNN, a user-supplied ONNX model), the blob classifier (human,
vehicle, clutter from dispersedness, area and metric size at the geolocated foot point),
the per-camera blob tracker, the pipeline from a video to
:class:`~demtrack.core.tracking.types.Detection` records, and the KLV parser and encoder.
May import ``core.camera``, ``core.geolocation``, ``core.geo``, ``core.tracking.types``,
``core.io`` and ``core.errors``; never the server, the CLI or the sample-site generator.
"""
