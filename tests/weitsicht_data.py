"""Where the real weitsicht data is (read-only, Apache-2.0; never copied into the repo).

``$DEMTRACK_WEITSICHT_DATA``, else ``shared/data/weitsicht`` beside the checkout (or one
level further up, for a worktree), else ``/work/shared/data/weitsicht``. Tests that need
it skip, naming this folder, where none holds ``cases.json``.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["WEITSICHT_DIR"]

_REPO = Path(__file__).resolve().parents[1]


def _find() -> Path:
    env = os.environ.get("DEMTRACK_WEITSICHT_DATA")
    if env:
        return Path(env)
    candidates = [
        _REPO.parent / "shared" / "data" / "weitsicht",
        _REPO.parent.parent / "shared" / "data" / "weitsicht",
        Path("/work/shared/data/weitsicht"),
    ]
    return next((c for c in candidates if (c / "cases.json").is_file()), candidates[-1])


WEITSICHT_DIR = _find()
