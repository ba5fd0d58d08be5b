"""Stored track bodies are assembled from cached point encodings: the same text as encoding
the whole body at once.

A live track changes with almost every batch; re-encoding all its points each time made the
cost of a batch grow with the length of the tracks. The pipeline keeps each point's JSON and
splices the body together. Oracle: ``json.dumps`` of the body the pipeline builds, checked
for every track row written over a replay in which tracks grow, are smoothed and end.
"""

from __future__ import annotations

import itertools
import json

import pytest

from demtrack.core.site import load_site
from demtrack.server.db import Store, dumps_json
from demtrack.server.pipeline import Pipeline
from demtrack.server.replay import scenario_stream

pytestmark = pytest.mark.timeout(600)


def test_spliced_bodies_equal_whole_encodings(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    p = Pipeline(site, Store(tmp_path / "s.sqlite3"), "kalman", lambda _m: None)
    p.start()
    written: list[tuple[int, str, str]] = []
    body_json = p._body_json

    def checked(body):
        text = body_json(body)
        written.append((body["id"], text, dumps_json(body)))
        return text

    p._body_json = checked  # type: ignore[method-assign]
    frames = scenario_stream(site, ["passing-vehicles"], 0.0, rate_hz=5.0, duration_s=60.0)
    for _, group in itertools.groupby(frames, key=lambda f: int(2 * f.t_s)):
        p.ingest([r for f in group for r in f.records])
    assert len(written) > 50
    for _, spliced, whole in written:
        assert spliced == whole
    # Tracks were re-written as they grew (the cache was reused), and what is stored is the
    # newest text of each.
    ids = [i for i, _, _ in written]
    assert len(ids) > 3 * len(set(ids))
    newest = {i: json.loads(text) for i, text, _ in written}
    assert {t["id"]: t for t in p.store.tracks()} == newest
