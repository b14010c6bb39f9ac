"""cfclient's Lighthouse system configuration (``system-config.yaml``): reader and writer.

The document (Bitcraze's cfclient and cflib read and write it; docs/export.md):

- ``type: lighthouse_system_configuration``, ``version: '1'`` (a string), ``systemType``
  1 (LH1) or 2 (LH2);
- ``geos.<bs>``: ``origin`` (3 floats, m, world) and ``rotation`` (3x3, rows; the station
  frame into the world: ``p_world = rotation @ p_bs + origin``). cflib's station frame is ours
  (SPEC §4: +x forward, +y left, +z up; azimuth ``atan2(y, x)``, elevation ``atan2(z, x)``),
  so a geometry is exactly ``T_world_lh``: verified on the shared LH1 log, where crossing
  beams from the log's ``correctedAngle`` through the file's geometry read this way
  reproduce the firmware's own ``lhCrossingBeam`` positions (docs/export.md);
- ``calibs.<bs>``: ``sweeps`` (two tables, sweep 0 and 1, with ``phase, tilt, curve,
  gibmag, gibphase, ogeemag, ogeephase`` in Bitcraze's convention) and ``uid`` (the
  station's 32-bit id).

:func:`read_system_config` and :func:`write_system_config` work in our types
(:class:`SystemConfig`: ``T_world_lh`` and our model's factory calibration); the mapping of
the calibration terms between Bitcraze's convention and ours lives in
:mod:`lhgraph.model.bitcraze` only. ``<bs>`` is the base-station index (an integer key), the
station index of our files. The calibrations of an LH2 system (systemType 2) are
generation-2 :class:`StationCalibration` objects.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.io.files import read_input, write_atomic
from lhgraph.model.bitcraze import (
    calibration_from_bitcraze,
    calibration_to_bitcraze,
    lh2_calibration_from_bitcraze,
    lh2_calibration_to_bitcraze,
    pose_from_bitcraze,
    pose_to_bitcraze,
)
from lhgraph.model.calibration import StationCalibration
from lhgraph.model.station import FactoryCalibration

Array = NDArray[np.float64]
CalibrationMapping = tuple[Callable[[Sequence[dict[str, float]], str], FactoryCalibration],
                Callable[[FactoryCalibration], list[dict[str, float]]]]

FILE_TYPE = "lighthouse_system_configuration"
FILE_VERSION = "1"
SYSTEM_TYPES = {1: "LH1", 2: "LH2"}
CALIBRATION_MAPPINGS: dict[int, CalibrationMapping] = {
    1: (calibration_from_bitcraze, calibration_to_bitcraze),
    2: (lh2_calibration_from_bitcraze, lh2_calibration_to_bitcraze),
}
"""Per system type (= station generation), Bitcraze's calibration terms -> ours and back."""
MAX_ORTHONORMAL_ERROR = 1e-3
"""A rotation is accepted when ``|R^T R - I|`` stays below this (float32 files reach 1e-7)."""


@dataclass(frozen=True)
class SystemConfig:
    """A cfclient system configuration in our types: ``system_type`` (1 = LH1, 2 = LH2),
    the station poses ``T_world_lh`` (4x4) and the factory calibrations (our model's terms;
    ``id`` is Bitcraze's ``uid``), keyed by base-station index."""

    system_type: int = 1
    T_world_lh: dict[int, Array] = field(default_factory=dict)
    calibrations: dict[int, StationCalibration] = field(default_factory=dict)


def _floats(value: Any, n: int, source: Path, where: str) -> list[float]:
    if (not isinstance(value, list) or len(value) != n
            or not all(isinstance(v, int | float) and not isinstance(v, bool)
                       and math.isfinite(v) for v in value)):
        raise InputError(f"expected a list of {n} finite numbers, got {value!r}", source, where)
    return [float(v) for v in value]


def _table(value: Any, source: Path, where: str) -> dict[Any, Any]:
    if not isinstance(value, dict):
        raise InputError(f"expected a mapping, got {value!r}", source, where)
    return value


def _index(key: Any, source: Path, where: str) -> int:
    if isinstance(key, bool) or not isinstance(key, int) or key < 0:
        raise InputError(f"base-station index must be an integer >= 0, got {key!r}", source,
                         where)
    return key


def check_rotation(R: Array, source: str | Path | None, where: str) -> None:
    """InputError unless ``R`` (3x3) is a proper rotation (orthonormal, det +1)."""
    if (not np.all(np.isfinite(R))
            or np.max(np.abs(R.T @ R - np.eye(3))) > MAX_ORTHONORMAL_ERROR
            or np.linalg.det(R) < 0):
        raise InputError("not a rotation matrix (orthonormal, determinant +1)", source, where)


def _geometry(value: Any, source: Path, where: str) -> Array:
    geo = _table(value, source, where)
    for key in ("origin", "rotation"):
        if key not in geo:
            raise InputError(f"missing key '{key}'", source, where)
    origin = _floats(geo["origin"], 3, source, f"{where}.origin")
    rows = geo["rotation"]
    if not isinstance(rows, list) or len(rows) != 3:
        raise InputError(f"expected 3 rows of 3 numbers, got {rows!r}", source,
                         f"{where}.rotation")
    R = np.array([_floats(r, 3, source, f"{where}.rotation") for r in rows])
    check_rotation(R, source, f"{where}.rotation")
    return pose_from_bitcraze(origin, R)


def _calibration(value: Any, system_type: int, source: Path, where: str) -> StationCalibration:
    calib = _table(value, source, where)
    sweeps = calib.get("sweeps")
    if not isinstance(sweeps, list) or len(sweeps) != 2:
        raise InputError(f"'sweeps' must be a list of 2 tables, got {sweeps!r}", source, where)
    for k, sweep in enumerate(sweeps):
        for key, v in _table(sweep, source, f"{where}.sweeps[{k}]").items():
            _floats([v], 1, source, f"{where}.sweeps[{k}].{key}")
    uid = calib.get("uid", 0)
    if isinstance(uid, bool) or not isinstance(uid, int) or not 0 <= uid < 2**32:
        raise InputError(f"uid must be an unsigned 32-bit integer, got {uid!r}", source,
                         f"{where}.uid")
    from_bitcraze = _mapping(system_type, source)[0]
    return StationCalibration(from_bitcraze(sweeps, f"{source}:{where}"), uid,
                              generation=system_type)


def _mapping(system_type: int, source: str | Path | None) -> CalibrationMapping:
    """The calibration mapping of ``system_type``; InputError for an unknown or not yet
    supported one."""
    if system_type not in SYSTEM_TYPES:
        raise InputError(f"systemType must be 1 (LH1) or 2 (LH2), got {system_type!r}", source,
                         "systemType")
    return CALIBRATION_MAPPINGS[system_type]


def read_system_config(path: str | Path) -> SystemConfig:
    """Read and validate a cfclient ``system-config.yaml``."""
    path = Path(path)
    text = read_input(path, "a YAML file")
    try:
        data = yaml.safe_load(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise InputError("not a text file", path) from None
    except yaml.YAMLError as exc:
        problem = str(exc).splitlines()[0] if str(exc) else "syntax error"
        raise InputError(f"not valid YAML ({problem})", path) from None
    data = _table(data, path, "top level")
    if data.get("type") != FILE_TYPE:
        raise InputError(f"type must be '{FILE_TYPE}', got {data.get('type')!r}", path, "type")
    if str(data.get("version")) != FILE_VERSION:
        raise InputError(f"unsupported version {data.get('version')!r} (expected "
                         f"'{FILE_VERSION}')", path, "version")
    system_type = data.get("systemType", 2)  # cflib's default when the key is absent
    _mapping(system_type, path)
    geos = {_index(k, path, f"geos.{k}"): _geometry(v, path, f"geos.{k}")
            for k, v in _table(data.get("geos") or {}, path, "geos").items()}
    calibs = {_index(k, path, f"calibs.{k}"): _calibration(v, system_type, path, f"calibs.{k}")
              for k, v in _table(data.get("calibs") or {}, path, "calibs").items()}
    return SystemConfig(int(system_type), geos, calibs)


def system_config_document(config: SystemConfig) -> dict[str, Any]:
    """The YAML document of ``config`` as plain Python values (checked: proper rotations,
    a supported system type, 32-bit uids)."""
    to_bitcraze = _mapping(config.system_type, None)[1]
    geos = {}
    for k in sorted(config.T_world_lh):
        T = np.asarray(config.T_world_lh[k], dtype=float)
        check_rotation(T[:3, :3], None, f"station {k}")
        origin, rotation = pose_to_bitcraze(T)
        geos[int(k)] = {"origin": origin, "rotation": rotation}
    calibs = {}
    for k in sorted(config.calibrations):
        c = config.calibrations[k]
        if not 0 <= c.id < 2**32:
            raise InputError(f"id {c.id} is not an unsigned 32-bit integer (Bitcraze's uid)",
                             None, f"station {k}")
        calibs[int(k)] = {"sweeps": to_bitcraze(c.calibration), "uid": int(c.id)}
    return {"type": FILE_TYPE, "version": FILE_VERSION, "systemType": int(config.system_type),
            "geos": geos, "calibs": calibs}


def write_system_config(config: SystemConfig, path: str | Path, overwrite: bool = False
                        ) -> Path:
    """Write ``config`` as a cfclient ``system-config.yaml`` (atomically)."""
    text = yaml.safe_dump(system_config_document(config), default_flow_style=False,
                          sort_keys=True)
    return write_atomic(path, text.encode(), overwrite)
