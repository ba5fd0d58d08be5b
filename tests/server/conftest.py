"""Fixtures for the server tests: apps on the sample site with a fresh database each."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from server_helpers import make_app


@pytest.fixture
def client_factory(sample_site_dir: Path, tmp_path: Path) -> Iterator[Callable[..., TestClient]]:
    """``client_factory(**settings)`` -> a started TestClient on a fresh database."""
    clients: list[TestClient] = []

    def make(**overrides: Any) -> TestClient:
        c = TestClient(make_app(sample_site_dir, tmp_path, **overrides))
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
def ro_client(sample_site_dir: Path, tmp_path_factory) -> Iterator[TestClient]:
    """One client per module for read-only tests."""
    with TestClient(make_app(sample_site_dir, tmp_path_factory.mktemp("ro"))) as c:
        yield c
