"""``core/`` and ``server/`` type-check clean under mypy (config: pyproject.toml [tool.mypy]).

mypy runs in a subprocess with this interpreter, from the repository root, so it reads the
project's own configuration and sees the installed third-party packages. Its incremental
cache goes to ``.mypy_cache/`` at the root (git-ignored): warm runs take about a second,
a cold run (fresh clone, as on CI) tens of seconds.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TARGETS = ("core", "server")


def test_core_and_server_type_check_clean():
    if importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed (it is in the dev dependency group: uv sync --dev)")
    cmd = [
        sys.executable,
        "-m",
        "mypy",
        "--config-file",
        str(ROOT / "pyproject.toml"),
        "--cache-dir",
        str(ROOT / ".mypy_cache"),
        "--no-color-output",
        "--no-pretty",
        *TARGETS,
    ]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=540)
    out = proc.stdout + proc.stderr
    errors = [line for line in out.splitlines() if ": error:" in line]
    if proc.returncode != 0 or errors:
        listing = "\n".join(errors) if errors else out.strip()
        pytest.fail(
            f"mypy {' '.join(TARGETS)} exited {proc.returncode} with "
            f"{len(errors)} error(s):\n{listing}",
            pytrace=False,
        )
