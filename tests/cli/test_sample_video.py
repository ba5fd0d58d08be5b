"""``demtrack sample-video``: a short clip's MP4, its timestamps and its true boxes."""

from __future__ import annotations

import json

import av
import numpy as np
import pytest

from demtrack.cli import main
from demtrack.core.io.times import parse_iso_time
from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import SCENARIOS, site_world, true_cameras
from demtrack.samplesite.video_file import read_video_truth
from demtrack.samplesite.video_render import FrameRenderer
from demtrack.samplesite.video_scene import camera_scene

START = "2026-12-01T14:30:00Z"


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def clip(sample_site_dir, tmp_path_factory):
    """Two seconds of the vehicle run from cam1 (the car on the entrance road)."""
    out = tmp_path_factory.mktemp("video") / "run.mp4"
    status = main(
        [
            "sample-video", "--site", str(sample_site_dir), "--scenario", "vehicle-run",
            "--sensor", "cam1", "-o", str(out), "--start", START, "--t-from", "8.25",
            "--t-to", "10.2", "--seed", "4",
        ]
    )  # fmt: skip
    assert status == 0
    return out


def test_clip_frames_carry_the_scenario_times(clip):
    truth = read_video_truth(clip.with_name("run.truth.jsonl"))
    start_s = parse_iso_time(START, "start")
    assert truth.header["rate_hz"] == 10.0 and truth.sensor == "cam1"
    assert [f["frame"] for f in truth.frames] == list(range(20))
    expected = start_s + 8.25 + np.arange(20) / 10.0
    np.testing.assert_allclose([f["t_s"] for f in truth.frames], expected, atol=1e-6)
    with av.open(str(clip)) as container:
        created = container.metadata["creation_time"]
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264"
        assert (stream.codec_context.width, stream.codec_context.height) == (1280, 720)
        times = [float(f.time) for f in container.decode(video=0)]
    # creation_time is a whole second (MP4 keeps no fraction); PTS carry the rest.
    created_s = parse_iso_time(created, "creation_time")
    assert created_s == np.floor(start_s + 8.25)
    np.testing.assert_allclose(created_s + np.array(times), expected, atol=1e-3)


def test_clip_pixels_are_the_render(clip, sample_site_dir):
    """The decoded frames are the renderer's (H.264 loses a little) and hold the car."""
    truth = read_video_truth(clip.with_name("run.truth.jsonl"))
    site = load_site(sample_site_dir)
    world = site_world(site)
    scene = camera_scene(site, world, true_cameras(site)["cam1"])
    renderer = FrameRenderer(scene, world, SCENARIOS["vehicle-run"](world), seed=4)
    with av.open(str(clip)) as container:
        decoded = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(decoded) == 20
    for k in (0, 19):
        image, boxes = renderer.render(8.25 + k / 10.0)
        assert np.abs(decoded[k].astype(float) - image).mean() < 3.0
        (row,) = truth.frames[k]["targets"]
        assert row["class"] == "vehicle" and row["counted"]
        assert row["bbox"] == pytest.approx(list(boxes[0].bbox), abs=0.01)
        u0, v0, u1, v1 = (int(round(x)) for x in row["bbox"])
        car = decoded[k][v0 + 2 : v1 - 2, u0 + 2 : u1 - 2].astype(float)
        road = decoded[k][v1 + 4 : v1 + 8, u0:u1].astype(float)
        # The car's body is red, unlike the grey road and green field around it.
        assert (car[..., 0] - car[..., 1]).max() > 60 and (road[..., 0] - road[..., 1]).max() < 30
    json.loads(clip.with_name("run.truth.jsonl").read_text().splitlines()[0])


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--sensor", "cam9"], "unknown sensor 'cam9'"),
        (["--sensor", "cam1", "-o", "x.avi"], "unknown file type '.avi'"),
        (["--sensor", "cam1", "--t-from", "5", "--t-to", "2"], "--t-to 2 is before --t-from 5"),
        (["--sensor", "cam1", "--start", "yesterday"], "--start"),
    ],
)
def test_mistakes_are_one_line(capsys, sample_site_dir, tmp_path, extra, message):
    argv = ["sample-video", "--site", sample_site_dir, "--scenario", "pedestrians"]
    if "-o" not in extra:
        extra = [*extra, "-o", tmp_path / "x.mp4"]
    status, _, err = run(capsys, *argv, *extra)
    assert status == 2 and message in err and len(err.strip().splitlines()) == 1
