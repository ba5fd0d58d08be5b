"""Reading GeoJSON FeatureCollections with one-line errors (shared by roads and zones)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..errors import InputFileError

__all__ = ["read_features"]


def read_features(path: str | Path, what: str) -> list[dict[str, Any]]:
    """The features of a GeoJSON FeatureCollection file; ``what`` names it in errors.

    Raises
    ------
    InputFileError
        Missing or unreadable file, invalid JSON, or not a FeatureCollection.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputFileError(f"cannot read {what} file {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise InputFileError(f"{what} file {path} is not valid JSON: {exc.msg}") from None
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise InputFileError(f"{what} file {path} must be a GeoJSON FeatureCollection")
    return [f if isinstance(f, dict) else {} for f in doc.get("features") or []]
