"""The soak stops when its replay is over, and leaves the idle samples out."""

from __future__ import annotations

import dataclasses
import math

from demtrack.bench.console_soak import Sample, _replay_ended


def _sample(wall_s: float, detections: int) -> Sample:
    values = {f.name: 0 for f in dataclasses.fields(Sample)}
    return Sample(
        **{
            **values,
            "wall_s": wall_s,
            "t_s": wall_s * 10,
            "pace": math.nan,
            "detections": detections,
        }
    )


def test_a_replay_ends_after_two_samples_without_detections():
    samples = [_sample(10 * i, n) for i, n in enumerate([0, 50, 100, 150])]
    assert not _replay_ended(samples)
    samples.append(_sample(40, 150))
    assert not _replay_ended(samples)  # one quiet sample: a pause, not the end
    samples.append(_sample(50, 150))
    assert _replay_ended(samples)
    assert [s.detections for s in samples] == [0, 50, 100, 150]  # idle samples dropped


def test_no_data_yet_is_not_an_end():
    samples = [_sample(10 * i, 0) for i in range(5)]
    assert not _replay_ended(samples)
    assert len(samples) == 5
