"""The soak stops when its replay is over, leaves the idle samples out, and reports the lag."""

from __future__ import annotations

import argparse
import dataclasses
import math
import re

from demtrack.bench.console_soak import Sample, _replay_ended, verdict


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


def _lag_growth(lags: list[float]) -> float:
    samples = [
        dataclasses.replace(
            _sample(30.0 * (i + 1), 1000 * (i + 1)), t_s=300.0 * (i + 1) - lag, lag_s=lag
        )
        for i, lag in enumerate(lags)
    ]
    args = argparse.Namespace(speed=10.0, rate_hz=10.0)
    first = verdict(samples, {}, args)[0]
    found = re.search(r"lag growth over the second half ([-+]\d+\.\d) s per scenario hour", first)
    assert found, first
    return float(found.group(1))


def test_the_verdict_tells_a_steady_lag_from_a_growing_one():
    # A page a few seconds behind the replay all along: the pace reads just under 10x,
    # but the lag does not grow.
    assert _lag_growth([5.0] * 8) == 0.0
    # A server falling behind: 10 s more lag per 30 s of wall, in which it replays 290 s
    # of scenario: 3600 / 290 * 10 = 124.1 s more per scenario hour.
    assert _lag_growth([10.0 * (i + 1) for i in range(8)]) == 124.1
