"""Writing into a site folder without ever leaving a half-written file.

Every file is written to a temporary name in the same folder and moved over the target
with :func:`os.replace` (atomic on POSIX and Windows), so a reader sees the old file or
the new one, never a mixture; on failure the temporary file is removed. ``site.json`` is
updated last, after the files it points to are in place.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import SiteError
from ..geo.geodesy import LocalFrame
from ..terrain.dem import Dem
from .folder import MANIFEST, SITE_FORMAT, SITE_FORMAT_VERSION

__all__ = [
    "new_manifest",
    "read_manifest",
    "write_atomic",
    "write_dem_atomic",
    "write_manifest",
]


def write_atomic(path: str | Path, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp)`` for a temporary path beside ``path``, then move it over ``path``.

    Raises whatever ``write`` raises, after removing the temporary file.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.part")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_dem_atomic(path: str | Path, dem: Dem) -> None:
    """:meth:`Dem.write` through :func:`write_atomic`."""
    write_atomic(path, dem.write)


def read_manifest(root: str | Path) -> dict[str, Any]:
    """The raw ``site.json`` document of a site folder (not checked beyond being JSON)."""
    manifest = Path(root) / MANIFEST
    try:
        doc = json.loads(manifest.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SiteError(f"not a site folder (no {MANIFEST}): {root}") from None
    except json.JSONDecodeError as exc:
        raise SiteError(f"{manifest} is not valid JSON: {exc.msg} (line {exc.lineno})") from None
    if not isinstance(doc, dict):
        raise SiteError(f"{manifest}: must hold a JSON object")
    return doc


def write_manifest(root: str | Path, doc: dict[str, Any]) -> None:
    """Write ``site.json`` atomically (indented, UTF-8, trailing newline)."""
    text = json.dumps(doc, indent=2) + "\n"
    write_atomic(Path(root) / MANIFEST, lambda p: p.write_text(text, encoding="utf-8"))


def new_manifest(
    name: str, frame: LocalFrame, geoid_undulation_m: float, dem: str = "dem.tif"
) -> dict[str, Any]:
    """``site.json`` for a new site with a DEM and no sensors yet."""
    return {
        "format": SITE_FORMAT,
        "version": SITE_FORMAT_VERSION,
        "name": name,
        "frame": frame.to_dict(),
        "geoid_undulation_m": float(geoid_undulation_m),
        "dem": dem,
        "sensors": [],
    }
