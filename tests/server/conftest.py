"""Fixtures for the server tests: apps on the sample site with a fresh database each.

Every test that asks for ``store_backend`` (directly or through ``client_factory``,
``client``, ``ro_client``, ``store_kw`` or ``module_store_kw``) runs twice: on a SQLite
file (``[sqlite]``) and on a PostgreSQL database of the session's server (``[postgres]``,
docs/postgres.md). A test whose promise is the SQLite file's own (deleting or replacing
the file, its schema, a full disk) says so with ``@pytest.mark.sqlite_only("reason")``
and runs on SQLite only.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from server_helpers import make_app

BACKENDS = ("sqlite", "postgres")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "sqlite_only(reason): the test's promise is the SQLite file's; not on PostgreSQL"
    )


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "store_backend" not in metafunc.fixturenames:
        return
    marker = metafunc.definition.get_closest_marker("sqlite_only")
    if marker is not None and not (marker.args and str(marker.args[0]).strip()):
        raise pytest.UsageError(f"{metafunc.definition.nodeid}: sqlite_only needs a reason")
    backends = ["sqlite"] if marker is not None else list(BACKENDS)
    metafunc.parametrize("store_backend", backends, indirect=True, scope="module")


@pytest.fixture(scope="module")
def store_backend(request: pytest.FixtureRequest) -> str:
    """``"sqlite"`` or ``"postgres"``: the store the test's apps open."""
    return str(request.param)


def _store_settings(backend: str, request: pytest.FixtureRequest) -> dict[str, Any]:
    if backend == "sqlite":
        return {}  # make_app's SQLite file under the test's folder
    cluster = request.getfixturevalue("postgres_cluster")
    return {"database_url": cluster.create_store_database()}


@pytest.fixture
def store_kw(store_backend: str, request: pytest.FixtureRequest) -> dict[str, Any]:
    """Settings selecting the test's database, for ``make_app(site, tmp, **store_kw)``:
    nothing on SQLite (the file ``tmp/console.sqlite3``), a fresh migrated PostgreSQL
    database's ``database_url`` on PostgreSQL (the same one for every app of the test, as
    the file is)."""
    return _store_settings(store_backend, request)


@pytest.fixture(scope="module")
def module_store_kw(store_backend: str, request: pytest.FixtureRequest) -> dict[str, Any]:
    """:func:`store_kw` for a module's shared app."""
    return _store_settings(store_backend, request)


@pytest.fixture
def client_factory(
    sample_site_dir: Path, tmp_path: Path, store_kw: dict[str, Any]
) -> Iterator[Callable[..., TestClient]]:
    """``client_factory(**settings)`` -> a started TestClient on the test's database."""
    clients: list[TestClient] = []

    def make(**overrides: Any) -> TestClient:
        c = TestClient(make_app(sample_site_dir, tmp_path, **{**store_kw, **overrides}))
        c.__enter__()
        clients.append(c)
        return c

    yield make
    for c in clients:
        c.__exit__(None, None, None)


@pytest.fixture
def client(client_factory) -> TestClient:
    """A started client, token configured, reads closed."""
    return client_factory()


@pytest.fixture(scope="module")
def ro_client(
    sample_site_dir: Path, tmp_path_factory, module_store_kw: dict[str, Any]
) -> Iterator[TestClient]:
    """One client per module for read-only tests."""
    with TestClient(
        make_app(sample_site_dir, tmp_path_factory.mktemp("ro"), **module_store_kw)
    ) as c:
        yield c
