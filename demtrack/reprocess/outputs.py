"""A run's outputs: the tracks file, the fixes as Parquet, the manifest and content hash.

Tracks get run-wide ids: segment by segment in plan order (group, then time), each
segment's tracks in their tracker's id order, numbered from 1. Every point's
``fix_indices`` are detection ids (the archive's canonical order). The content hash is
sha256 over the outputs' names and sha256s (the manifest is not part of it: it also
says how long the run took, with which engine).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

from demtrack.core.tracking import Track

from .engines import RunResult
from .plan import Plan
from .tasks import GeoResult

__all__ = ["content_hash", "file_sha256", "merged_tracks", "write_outputs"]

FIXES_NAME = "fixes.parquet"
MANIFEST_NAME = "manifest.json"


def merged_tracks(result: RunResult) -> list[Track]:
    """Every segment's tracks with run-wide ids (module notes)."""
    out: list[Track] = []
    for seg_tracks in result.tracks:
        for t in sorted(seg_tracks, key=lambda t: t.id):
            out.append(replace(t, id=len(out) + 1))
    return out


def file_sha256(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def content_hash(files: dict[str, str]) -> str:
    """sha256 over ``name sha256`` lines of the outputs, sorted by name."""
    text = "".join(f"{name} {sha}\n" for name, sha in sorted(files.items()))
    return hashlib.sha256(text.encode()).hexdigest()


def write_outputs(
    out_dir: Path,
    result: RunResult,
    plan: Plan,
    *,
    tracks_name: str,
    write_tracks: Callable[[Sequence[Track], Path], None],
    info: dict[str, Any],
    run: dict[str, Any],
) -> dict[str, Any]:
    """Write tracks, fixes and the manifest into ``out_dir``; returns the manifest.

    Parameters
    ----------
    tracks_name : str
        The tracks file's name (its suffix picks the format).
    write_tracks : callable
        ``(tracks, path)``: the track writer (``demtrack track``'s).
    info : dict
        What the run was asked (method, archive, counts): in the manifest and hashed
        only through the outputs.
    run : dict
        How it ran (engine, workers, seconds): in the manifest, not in the hash.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    tracks = merged_tracks(result)
    tracks_path = out_dir / tracks_name
    write_tracks(tracks, tracks_path)
    geo = GeoResult.merged(result.geo)
    fixes = geo.fixes.sorted()
    pq.write_table(fixes.to_arrow(), out_dir / FIXES_NAME, compression="zstd")
    names = [tracks_name, FIXES_NAME]
    if tracks_path.with_suffix(".csvt").exists() and tracks_path.suffix.lower() == ".csv":
        names.append(tracks_path.with_suffix(".csvt").name)
    files = {n: file_sha256(out_dir / n) for n in names}
    manifest = {
        "format": "demtrack.reprocess",
        "version": 1,
        **info,
        "n_fixes": len(fixes),
        "n_tracks": len(tracks),
        "geolocation_skipped": dict(sorted(geo.counts.items())),
        "groups": [list(g) for g in plan.groups],
        "n_segments": len(plan.segments),
        "n_jobs": len(plan.jobs),
        "n_parts": len(plan.parts),
        "quiet_s": plan.quiet_s,
        "window_s": plan.window_s,
        "chunk_s": plan.chunk_s,
        "files": files,
        "content_hash": content_hash(files),
        "run": run,
    }
    (out_dir / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return manifest
