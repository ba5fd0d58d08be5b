"""One table of target heights: the CLI, the API and the core agree on it."""

from __future__ import annotations

import inspect

from demtrack.core.visibility.target_heights import (
    DEFAULT_TARGET_HEIGHT_M,
    TARGET_HEIGHT_M,
    target_height_for,
)
from demtrack.core.visibility.viewshed import viewshed
from demtrack.server.api import visibility as visibility_router


def test_classes_and_default():
    assert TARGET_HEIGHT_M == {"human": 1.7, "vehicle": 1.5}
    assert DEFAULT_TARGET_HEIGHT_M == 1.7
    assert target_height_for("human") == 1.7
    assert target_height_for("vehicle") == 1.5
    assert target_height_for(None) == 1.5
    assert target_height_for("unknown") == 1.5


def test_core_api_and_cli_defaults_agree():
    from demtrack.cli import build_parser

    core_default = inspect.signature(viewshed).parameters["target_height_m"].default
    endpoints = [
        visibility_router.sensor_viewshed,
        *(
            getattr(visibility_router, name)
            for name in dir(visibility_router)
            if name.startswith("coverage")
        ),
    ]
    api_defaults = {
        inspect.signature(f).parameters["target_height_m"].default
        for f in endpoints
        if callable(f) and "target_height_m" in inspect.signature(f).parameters
    }
    args = build_parser().parse_args(["viewshed", "--site", "x", "-o", "y.tif"])
    assert core_default == DEFAULT_TARGET_HEIGHT_M
    assert api_defaults == {DEFAULT_TARGET_HEIGHT_M}
    assert args.target_height == DEFAULT_TARGET_HEIGHT_M
