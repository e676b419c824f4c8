"""Fixtures that start real node processes on 127.0.0.1 (shared by every integration test).

``cluster`` gives a :class:`tests.integration.cluster.Cluster`, its processes killed at teardown.
Test modules import the class and its helpers from ``tests.integration.cluster``, not from this
file: a bare ``conftest`` module name is the first conftest.py pytest imported, which in one run of
unit and integration tests together may be tests/unit/conftest.py.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.cluster import Cluster


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[Cluster]:
    """Node processes on 127.0.0.1, all killed at teardown."""
    c = Cluster(tmp_path)
    try:
        yield c
    finally:
        c.close()
