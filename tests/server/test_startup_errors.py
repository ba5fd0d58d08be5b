"""Start-up failures of ``demtrack serve`` and ``demtrack demo``: one line, exit 2.

Each case breaks one thing in a copy of the sample site (or its database) and starts the
real command line: the oracle is exit status 2, exactly one line on stderr naming the
file and the problem, no traceback, and no "Application startup failed" from uvicorn.
"""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(300)


def _manifest(site: Path) -> dict:
    return json.loads((site / "site.json").read_text())


def _write_manifest(site: Path, doc: dict) -> None:
    (site / "site.json").write_text(json.dumps(doc))


def corrupt_db(site: Path, db: Path) -> tuple[str, str]:
    db.write_bytes(b"this is not an SQLite database, just some bytes" * 100)
    return str(db), "database"


def newer_schema_db(site: Path, db: Path) -> tuple[str, str]:
    conn = sqlite3.connect(db)
    conn.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    conn.execute("INSERT INTO schema_version VALUES (999)")
    conn.commit()
    conn.close()
    return str(db), "newer"


def missing_roads(site: Path, db: Path) -> tuple[str, str]:
    rel = _manifest(site)["roads"]
    (site / rel).unlink()
    return rel, "missing"


def corrupt_roads(site: Path, db: Path) -> tuple[str, str]:
    rel = _manifest(site)["roads"]
    (site / rel).write_text('{"type": "FeatureCollection", "features": [{"type": ')
    return rel, "JSON"


def truncated_dem(site: Path, db: Path) -> tuple[str, str]:
    rel = _manifest(site)["dem"]
    data = (site / rel).read_bytes()
    (site / rel).write_bytes(data[: len(data) // 3])
    return rel, "truncated"


def manifest_without_frame(site: Path, db: Path) -> tuple[str, str]:
    doc = _manifest(site)
    del doc["frame"]
    _write_manifest(site, doc)
    return "site.json", "frame"


def manifest_without_dem(site: Path, db: Path) -> tuple[str, str]:
    doc = _manifest(site)
    del doc["dem"]
    _write_manifest(site, doc)
    return "site.json", "'dem'"


def image_leaving_the_site(site: Path, db: Path) -> tuple[str, str]:
    doc = _manifest(site)
    doc["sensors"][0]["image"] = "../../../../etc/passwd"
    _write_manifest(site, doc)
    return "site.json", "outside the site folder"


def broken_manifest_json(site: Path, db: Path) -> tuple[str, str]:
    (site / "site.json").write_text('{"format": "demtrack.site", ')
    return "site.json", "not valid JSON"


CASES: list[Callable[[Path, Path], tuple[str, str]]] = [
    corrupt_db,
    newer_schema_db,
    missing_roads,
    corrupt_roads,
    truncated_dem,
    manifest_without_frame,
    manifest_without_dem,
    image_leaving_the_site,
    broken_manifest_json,
]


def _broken_site(sample_site_dir: Path, tmp_path: Path, breaker) -> tuple[Path, Path, str, str]:
    site = tmp_path / "site"
    shutil.copytree(sample_site_dir, site, ignore=shutil.ignore_patterns("*.sqlite3*"))
    db = tmp_path / "console.sqlite3"
    named, problem = breaker(site, db)
    return site, db, named, problem


def _run(*argv: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "DEMTRACK_TOKEN": "startup-test-token"}
    return subprocess.run(
        [sys.executable, "-m", "demtrack.cli", *argv],
        capture_output=True,
        text=True,
        check=False,
        env=env,
        timeout=240,
    )


def _assert_one_line(proc: subprocess.CompletedProcess[str], named: str, problem: str) -> None:
    err = proc.stderr
    assert proc.returncode == 2, (proc.returncode, err[-3000:])
    assert err.count("\n") == 1 and err.startswith("demtrack "), err[-3000:]
    assert "Traceback" not in err and "Application startup failed" not in err, err
    assert named in err and problem in err, err


@pytest.mark.parametrize("breaker", CASES, ids=[c.__name__ for c in CASES])
def test_serve_start_up_failure_is_one_line(breaker, sample_site_dir: Path, tmp_path: Path):
    site, db, named, problem = _broken_site(sample_site_dir, tmp_path, breaker)
    proc = _run("serve", "--site", str(site), "--db", str(db), "--port", "0", "--no-warm-up")
    _assert_one_line(proc, named, problem)


@pytest.mark.parametrize("breaker", [corrupt_db, truncated_dem], ids=["corrupt_db", "dem"])
def test_demo_start_up_failure_is_one_line(breaker, sample_site_dir: Path, tmp_path: Path):
    site, db, named, problem = _broken_site(sample_site_dir, tmp_path, breaker)
    proc = _run("demo", "--site", str(site), "--db", str(db), "--keep-db", "--port", "0", "--no-3d")
    _assert_one_line(proc, named, problem)


def test_a_bad_setting_is_one_line(sample_site_dir: Path, tmp_path: Path):
    env_bad = {"DEMTRACK_REPLAY_SPEED": "-3"}
    proc = subprocess.run(
        [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(sample_site_dir),
         "--db", str(tmp_path / "c.sqlite3"), "--port", "0", "--no-warm-up"],
        capture_output=True, text=True, check=False, timeout=120,
        env={**os.environ, "DEMTRACK_TOKEN": "t", **env_bad},
    )  # fmt: skip
    _assert_one_line(proc, "DEMTRACK_REPLAY_SPEED", "greater than 0")


def test_a_newer_postgres_database_is_one_line(postgres_cluster, sample_site_dir: Path):
    """The PostgreSQL meaning of ``newer_schema_db``: a database a newer demtrack migrated."""
    import psycopg

    url = postgres_cluster.create_store_database()
    with psycopg.connect(url, autocommit=True) as conn:
        conn.execute("UPDATE schema_version SET version = 999")
    proc = _run("serve", "--site", str(sample_site_dir), "--database-url", url)
    _assert_one_line(proc, url, "newer")
