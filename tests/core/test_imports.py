"""The engine is a library: it imports without the web stack and does no work on import."""

from __future__ import annotations

import pkgutil
import subprocess
import sys

import demtrack.core


def test_core_imports_without_web_packages():
    modules = [m.name for m in pkgutil.walk_packages(demtrack.core.__path__, "demtrack.core.")]
    assert "demtrack.core.raycast.cast" in modules and "demtrack.core.tracking.tracker" in modules
    code = (
        "import importlib, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "web = ('fastapi', 'viser', 'uvicorn', 'starlette')\n"
        "bad = sorted(m for m in web if m in sys.modules)\n"
        "print(','.join(bad))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == ""
