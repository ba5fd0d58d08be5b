"""The server process tunes the cyclic garbage collector once it is up."""

from __future__ import annotations

import subprocess
import sys


def test_tuning_freezes_start_up_objects_and_raises_thresholds():
    code = (
        "import gc\n"
        "from demtrack.commands.serve import SERVER_GC_THRESHOLDS, tune_gc_for_serving\n"
        "assert gc.get_freeze_count() == 0\n"
        "tune_gc_for_serving()\n"
        "assert gc.get_threshold() == SERVER_GC_THRESHOLDS, gc.get_threshold()\n"
        "assert gc.get_freeze_count() > 1000\n"
        "assert gc.isenabled()\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
