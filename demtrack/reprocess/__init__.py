"""Archive reprocessing: Parquet detection archives and ``demtrack reprocess``.

An archive (detections of many sensors over months) is geolocated in parallel, in parts
of one sensor and one time chunk, and tracked in parallel, one task chain per group of
sensors whose fields of view overlap and per quiet-bounded segment of that group's time
line; within a segment, time windows run in sequence and hand the tracker's exact state
to the next. Random seeds come from the group and the segment only, so the outputs (and
their content hash) are the same whatever the engine (one process, or Dask with any
number of workers), the order tasks complete in, or a worker dying mid-run.

Modules: :mod:`.archive` (the Parquet layout, file and Parquet readers),
:mod:`.store_export` (a store's detections as an archive), :mod:`.sources` (any source
read into canonical order), :mod:`.fix_columns` (fixes as columns, between tasks),
:mod:`.groups` (sensor groups by footprint overlap), :mod:`.plan` (parts, segments,
windows, jobs, seeds), :mod:`.tasks` (what a worker runs), :mod:`.engines` (local and
Dask), :mod:`.outputs` (tracks, fixes, manifest, content hash), :mod:`.run` (one run,
archive to outputs), :mod:`.synth` (the 12-camera site and the synthetic archive).
May import ``demtrack.core``, ``demtrack.server`` (the store's read methods, the export
heights) and ``demtrack.samplesite``; the CLI passes it the track writer.
"""
