"""Every Python package in the tree is listed in pyproject.toml (a wheel would miss it)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_directory_is_declared():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    declared = set(cfg["packages"])
    found = set()
    for name, rel in cfg["package-dir"].items():
        for init in (ROOT / rel).rglob("__init__.py"):
            if "__pycache__" in init.parts:
                continue
            sub = init.parent.relative_to(ROOT / rel).parts
            found.add(".".join([name, *sub]))
    assert found - declared == set(), "add these to [tool.setuptools] packages"
