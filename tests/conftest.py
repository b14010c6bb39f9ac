"""Shared fixtures: paths to the real data beside the repository (tests skip when absent),
and simulated captures more than one test file uses."""

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


@pytest.fixture(scope="session")
def miscalibrated_imu():
    """An 8 s capture of the default board with an IMU whose gyro reads 0.5 / 0.47 / 0.52 of
    the rate (the hive tracker's reads ~0.48), whose stamps run 6 ms late and whose frame is
    turned by 1.54 deg from the board's."""
    import dataclasses

    from lhgraph.sim.imu import ImuConfig
    from lhgraph.sim.simulate import load_simulation_config, simulate

    config = dataclasses.replace(
        load_simulation_config(REPO / "configs/simulation/default.toml"),
        imu=ImuConfig(gyro_scale_x=0.5, gyro_scale_y=0.47, gyro_scale_z=0.52,
                      time_offset_s=0.006, rotation_x_rad=0.02, rotation_y_rad=-0.015,
                      rotation_z_rad=0.01))
    return simulate(config, 1)
