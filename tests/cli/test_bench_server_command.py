"""``demtrack bench server`` at a toy size: it starts a real server and prints its figures."""

from __future__ import annotations

import re

import pytest

from demtrack.cli import main

pytestmark = pytest.mark.timeout(900)


def test_bench_server_smoke(capsys, sample_site_dir):
    argv = ["bench", "server", "--site", str(sample_site_dir), "--detections", "120"]
    argv += ["--batch", "60", "--clients", "3", "--messages", "4", "--rate", "10"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    m = re.search(r"\(HTTP\):\s+(\d+) det/s \((\d+) in", out)
    assert m and int(m.group(1)) > 0 and int(m.group(2)) == 120
    assert re.search(r"durable storage only .*:\s+\d+ det/s", out)
    m = re.search(r"3 WebSocket clients, POST -> message: median [\d.]+ ms, p95 [\d.]+ ms", out)
    assert m and "100.0 % of messages seen" in out
