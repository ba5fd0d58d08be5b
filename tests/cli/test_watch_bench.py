"""``demtrack bench video`` at a toy size (it prints figures; nothing is timed here)."""

from __future__ import annotations

from demtrack.cli import main


def test_bench_video_smoke(capsys, tmp_path):
    assert main(["bench", "video", "--frames", "12", "--site", str(tmp_path / "none")]) == 0
    out = capsys.readouterr().out
    assert "watch path" in out and "OpenCV MOG2 alone" in out and "ratio" in out
    assert "image cues (no site found)" in out
