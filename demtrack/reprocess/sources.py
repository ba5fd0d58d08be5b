"""Every archive source read into one canonical table (:func:`read_archive`)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from demtrack.core.errors import InputFileError

from .archive import (
    ArchiveRead,
    checked_table,
    is_database,
    parquet_table,
    read_detection_file,
)
from .store_export import store_table

__all__ = ["read_archive"]


def read_archive(
    source: str | os.PathLike[str], sensors: Mapping[str, tuple[int, int]]
) -> ArchiveRead:
    """Read any archive source into canonical order (module notes).

    Parameters
    ----------
    source : str or path
        ``.jsonl`` / ``.ndjson`` / ``.csv`` file, ``.parquet`` file or dataset folder,
        a store's SQLite file (``.sqlite3``, ``.sqlite``, ``.db``) or a database URL.
    sensors : mapping of sensor id to (width, height)
        The site's sensors; rows of others are counted ``unknown_sensor``.

    Raises
    ------
    InputFileError
        A missing source, or one of an unknown kind.
    """
    text = os.fspath(source)
    if is_database(text):
        return checked_table(store_table(text), sensors)
    path = Path(text)
    if not path.exists():
        raise InputFileError(f"archive {path} does not exist")
    suffix = path.suffix.lower()
    if path.is_dir() or suffix == ".parquet":
        return checked_table(parquet_table(path), sensors)
    if suffix in (".jsonl", ".ndjson", ".csv"):
        return read_detection_file(path, sensors)
    raise InputFileError(
        f"unknown archive kind {suffix!r} (use .jsonl, .csv, .parquet, a dataset folder,"
        " a .sqlite3 store or a database URL)"
    )
