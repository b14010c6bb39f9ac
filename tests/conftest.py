"""Shared fixtures: paths to the real data beside the repository (tests skip when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``; skips the test when it is not there."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture(scope="session")
def hive_bag(shared_data: Path) -> Path:
    """The hive recording (no licence: only read from ../shared); skips when absent."""
    path = shared_data / "hive-env8" / "data8.11.bag"
    if not path.is_file():
        pytest.skip(f"hive recording not found at {path}")
    return path


@pytest.fixture(scope="session")
def hive_import(hive_bag: Path, tmp_path_factory: pytest.TempPathFactory):
    """The bag imported once per test session: (HiveImport, output directory)."""
    from lhgraph.importers.hive import import_hive

    out = tmp_path_factory.mktemp("hive")
    return import_hive(hive_bag, out), out
