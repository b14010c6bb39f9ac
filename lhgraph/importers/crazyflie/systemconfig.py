"""cfclient's system-configuration YAML (``lighthouse_system_configuration``): system type,
factory calibration per station and the station geometry cfclient estimated.
Conventions are mapped by :mod:`lhgraph.model.bitcraze`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.model.bitcraze import calibration_from_bitcraze, pose_from_bitcraze
from lhgraph.model.calibration import StationCalibration

LH2_ISSUE = "LH2 import comes with issue #15"


@dataclass(frozen=True)
class SystemConfig:
    """``system_type`` (1 = LH1, 2 = LH2), calibrations (ours) and ``T_world_lh`` of the
    stations cfclient placed (its world), keyed by base-station index."""

    system_type: int
    calibrations: dict[int, StationCalibration]
    T_world_lh: dict[int, NDArray[np.float64]]


def _index(key: object, path: Path, where: str) -> int:
    try:
        return int(key)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        raise InputError(f"station key {key!r} is not an index", path, where) from None


def read_system_config(path: str | Path) -> SystemConfig:
    """Read a cfclient system configuration; InputError (one line) on a bad file and for an
    LH2 system (not imported yet)."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid YAML ({str(exc).splitlines()[0]})", path) from None
    if not isinstance(data, dict) or data.get("type") != "lighthouse_system_configuration":
        raise InputError("not a cfclient lighthouse_system_configuration", path)
    system_type = data.get("systemType", 1)
    if system_type == 2:
        raise InputError(f"an LH2 system (systemType 2): {LH2_ISSUE}", path)
    if system_type != 1:
        raise InputError(f"systemType {system_type!r} is not 1 (LH1) or 2 (LH2)", path)
    calibrations = {}
    for key, table in (data.get("calibs") or {}).items():
        where = f"calibs.{key}"
        index = _index(key, path, where)
        if not isinstance(table, dict) or "sweeps" not in table:
            raise InputError("expected 'sweeps'", path, where)
        cal = calibration_from_bitcraze(table["sweeps"], f"{path}:{where}")
        calibrations[index] = StationCalibration(cal, int(table.get("uid", index)))
    poses = {}
    for key, table in (data.get("geos") or {}).items():
        where = f"geos.{key}"
        index = _index(key, path, where)
        try:
            poses[index] = pose_from_bitcraze(table["origin"], table["rotation"])
        except (KeyError, TypeError, ValueError):
            raise InputError("expected 'origin' (3 numbers) and 'rotation' (3x3)", path,
                             where) from None
    return SystemConfig(1, calibrations, poses)
