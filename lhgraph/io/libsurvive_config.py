"""libsurvive's configuration file (``config.json``): reader and writer.

libsurvive keeps the stations it has calibrated in ``~/.config/libsurvive/config.json``
(docs/interop.md gives the mapping key by key). Its reader (a tokenizer in the manner of
jsmn, not a strict JSON parser) takes a run of ``"key":value`` members *without* enclosing
braces: the global settings, then one group ``"lighthouseN":{...}`` per station, each
member's value a quoted string or an array of quoted strings. A value whose every element
reads fully as a base-10 integer becomes an integer entry; otherwise as floats. A group is
used only when its ``"index"`` equals its N. Per station:

- ``index`` (N), ``id`` (the 32-bit OOTX id, written by libsurvive as a signed decimal),
  ``mode`` (LH1: the station's A/B/C mode; LH2: its channel - 1);
- ``pose``: ``x y z qw qx qy qz`` (m; quaternion w first), the transform of libsurvive's
  lighthouse frame into its world (``p_world = R p_lh + t``);
- ``variance``: ``x y z`` position and ``rx ry rz`` axis-angle rotation variances (m^2,
  rad^2, world axes; diagonal only);
- ``accel``: the station's OOTX accelerometer vector;
- ``fcalphase fcaltilt fcalcurve fcalgibpha fcalgibmag fcalogeephase fcalogeemag``:
  ``[axis0, axis1]`` each, the OOTX values as broadcast (ours are the same numbers;
  libsurvive applies its own LH1 gib sign to them, docs/model.md);
- ``OOTXSet`` / ``PositionSet``: 1 when the calibration / the pose are known.

libsurvive's lighthouse frame looks along its -z with +y up and +x right (its LH1
reprojection: axis 0 ``-atan2(x, -z)``, axis 1 ``atan2(y, -z)``); ours looks along +x with
+y left and +z up (SPEC §4). :data:`R_SURVIVE_LH` turns one into the other. The world is
the same frame in both files: a pose keeps its world.

:func:`read_survive_config` and :func:`write_survive_config` work in our types
(:class:`SurviveConfig`: our ``T_world_lh``, covariance and factory calibration).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import make_pose, matrix_to_quat, quat_to_matrix
from lhgraph.io.files import read_input, write_atomic
from lhgraph.model.calibration import StationCalibration, check_ranges
from lhgraph.model.factory import CALIBRATION_KEYS, LH2_CALIBRATION_KEYS, FactoryCalibration

Array = NDArray[np.float64]

R_SURVIVE_LH = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
"""``R_survive_lh``: a vector of our station frame (x forward, y left, z up) in libsurvive's
lighthouse frame (x right, y up, z backward)."""
SURVIVE_KEYS = {"phase": "fcalphase", "tilt": "fcaltilt", "curve": "fcalcurve",
                "gibphase": "fcalgibpha", "gibmag": "fcalgibmag",
                "ogeephase": "fcalogeephase", "ogeemag": "fcalogeemag"}
"""Our factory-calibration term -> libsurvive's key (the values are the same numbers)."""
GENERATION_KEY = "lighthouse-gen"
_TOKEN = re.compile(r'"((?:[^"\\]|\\.)*)"|([{}\[\]:,])|([^\s{}\[\]:,"]+)|(\s+)')


@dataclass(frozen=True)
class SurviveLighthouse:
    """One station of a libsurvive config in our types: ``T_world_lh`` (our station frame;
    None when the file has no pose for it: ``PositionSet`` 0 or an all-zero pose), the
    covariance (6x6, our tangent space ``[omega, v]``; from the file's world-axis diagonal,
    None when the file gives no variance), the factory calibration (None when ``OOTXSet``
    is 0) and libsurvive's ``mode``."""

    T_world_lh: Array | None
    covariance: Array | None = None
    calibration: StationCalibration | None = None
    mode: int = 0


@dataclass(frozen=True)
class SurviveConfig:
    """A libsurvive config in our types: the stations' generation (1 or 2), its stations
    by index and what reading it left out (``notes``, one line each)."""

    generation: int = 1
    lighthouses: dict[int, SurviveLighthouse] = field(default_factory=dict)
    notes: tuple[str, ...] = ()


def pose_to_survive(T_world_lh: Array) -> list[float]:
    """libsurvive's ``pose`` (x y z qw qx qy qz) of our ``T_world_lh``."""
    T = np.asarray(T_world_lh, dtype=float)
    q = matrix_to_quat(T[:3, :3] @ R_SURVIVE_LH.T)
    q = q if q[0] >= 0 else -q
    return [float(x) for x in T[:3, 3]] + [float(x) for x in q]


def pose_from_survive(pose: Array) -> Array:
    """Our ``T_world_lh`` of libsurvive's ``pose`` (x y z qw qx qy qz, the quaternion
    normalised)."""
    pose = np.asarray(pose, dtype=float)
    q = pose[3:7] / np.linalg.norm(pose[3:7])
    return make_pose(quat_to_matrix(q) @ R_SURVIVE_LH, pose[:3])


def variance_to_survive(T_world_lh: Array, covariance: Array) -> list[float]:
    """libsurvive's ``variance`` (position then rotation, world axes, m^2 and rad^2) of our
    6x6 covariance in the tangent space ``[omega, v]`` of ``T_world_lh`` (right
    perturbations: both blocks turn into the world by the station's rotation)."""
    R = np.asarray(T_world_lh, dtype=float)[:3, :3]
    cov = np.asarray(covariance, dtype=float)
    rotation = np.diag(R @ cov[:3, :3] @ R.T)
    position = np.diag(R @ cov[3:, 3:] @ R.T)
    return [float(x) for x in position] + [float(x) for x in rotation]


def covariance_from_survive(T_world_lh: Array, variance: Array) -> Array:
    """Our 6x6 covariance (tangent space ``[omega, v]``) of libsurvive's world-axis
    ``variance`` (a diagonal: the correlations it does not hold stay zero)."""
    R = np.asarray(T_world_lh, dtype=float)[:3, :3]
    v = np.asarray(variance, dtype=float)
    cov = np.zeros((6, 6))
    cov[:3, :3] = R.T @ np.diag(v[3:6]) @ R
    cov[3:, 3:] = R.T @ np.diag(v[:3]) @ R
    return cov


def parse_survive_text(text: str, path: str | Path | None = None) -> dict[str, Any]:
    """The members of a libsurvive config as ``{key: str | list[str] | dict}`` (groups as
    nested dicts). Accepts libsurvive's own files (no enclosing braces, no commas between
    groups) and strict JSON (one enclosing object). InputError naming ``path`` on text
    that is neither."""
    tokens = []
    for m in _TOKEN.finditer(text):
        if m.group(4) is None:
            tokens.append(("s", m.group(1)) if m.group(1) is not None
                          else ("p", m.group(2)) if m.group(2) is not None
                          else ("s", m.group(3)))
    if sum(len(m.group(0)) for m in _TOKEN.finditer(text)) != len(text):
        raise InputError("not a libsurvive config (an unterminated string)", path)
    if tokens and tokens[0] == ("p", "{") and tokens[-1] == ("p", "}"):
        tokens = tokens[1:-1]
    members, end = _members(tokens, 0, path)
    if end != len(tokens):
        raise InputError("not a libsurvive config (an unmatched '}')", path)
    return members


def _members(tokens: list[tuple[str, str]], i: int, path: str | Path | None
             ) -> tuple[dict[str, Any], int]:
    """Parse ``"key": value`` members from ``tokens[i]`` up to a ``}`` (not consumed)."""
    out: dict[str, Any] = {}
    while i < len(tokens) and tokens[i] != ("p", "}"):
        if tokens[i] == ("p", ","):
            i += 1
            continue
        if tokens[i][0] != "s" or tokens[i + 1:i + 2] != [("p", ":")]:
            raise InputError(f"not a libsurvive config (expected \"key\": value near "
                             f"{tokens[i][1]!r})", path)
        key, i = tokens[i][1], i + 2
        if i >= len(tokens):
            raise InputError(f"not a libsurvive config ('{key}' has no value)", path)
        if tokens[i] == ("p", "{"):
            out[key], i = _members(tokens, i + 1, path)
            if i >= len(tokens):
                raise InputError(f"not a libsurvive config ('{key}': a '{{' never closed)",
                                 path)
            i += 1
        elif tokens[i] == ("p", "["):
            values, i = [], i + 1
            while i < len(tokens) and tokens[i] != ("p", "]"):
                if tokens[i][0] == "s":
                    values.append(tokens[i][1])
                elif tokens[i] != ("p", ","):
                    raise InputError(f"not a libsurvive config ('{key}': a nested value)",
                                     path)
                i += 1
            if i >= len(tokens):
                raise InputError(f"not a libsurvive config ('{key}': a '[' never closed)",
                                 path)
            out[key], i = values, i + 1
        elif tokens[i][0] == "s":
            out[key], i = tokens[i][1], i + 1
        else:
            raise InputError(f"not a libsurvive config ('{key}': unexpected "
                             f"{tokens[i][1]!r})", path)
    return out, i


def _number(value: Any, path: Path, where: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"not a number: {value!r}", path, where) from None
    if not math.isfinite(x):
        raise InputError(f"not a finite number: {value!r}", path, where)
    return x


def _integer(value: Any, path: Path, where: str) -> int:
    if not isinstance(value, str) or not re.fullmatch(r"-?\d+", value.strip()):
        raise InputError(f"not an integer: {value!r}", path, where)
    return int(value)


def _floats(group: dict[str, Any], key: str, n: int, path: Path, where: str) -> Array | None:
    """A group's array of ``n`` numbers (None when absent)."""
    if key not in group:
        return None
    value = group[key]
    if not isinstance(value, list) or len(value) != n:
        raise InputError(f"'{key}' must hold {n} numbers", path, f"{where}.{key}")
    return np.array([_number(v, path, f"{where}.{key}") for v in value])


def _generation(members: dict[str, Any], groups: dict[int, dict[str, Any]], path: Path
                ) -> tuple[int, list[str]]:
    """The stations' generation: ``lighthouse-gen`` 1 or 2, else (0 = libsurvive's
    auto-detection, or absent) 2 when any ogee term is set, else 1, with a note."""
    stated = _integer(members.get(GENERATION_KEY, "0"), path, GENERATION_KEY)
    if stated in (1, 2):
        return stated, []
    if stated != 0:
        raise InputError(f"must be 0, 1 or 2, got {stated}", path, GENERATION_KEY)
    ogee = any(np.any(found) for i, g in groups.items() for k in LH2_CALIBRATION_KEYS
               if (found := _floats(g, SURVIVE_KEYS[k], 2, path, f"lighthouse{i}")) is not None)
    generation = 2 if ogee else 1
    return generation, [f"{GENERATION_KEY} is 0 (libsurvive detects it): taken as "
                        f"LH{generation} ({'ogee terms set' if ogee else 'no ogee terms'})"]


def _lighthouse(group: dict[str, Any], index: int, generation: int, path: Path
                ) -> SurviveLighthouse:
    """One ``lighthouseN`` group in our types."""
    where = f"lighthouse{index}"
    stated = _integer(group.get("index", "-1"), path, f"{where}.index")
    if stated != index:
        raise InputError(f"index is {stated}: libsurvive reads a lighthouseN group only when "
                         "its index is N", path, f"{where}.index")
    pose = _floats(group, "pose", 7, path, where)
    position_set = _integer(group.get("PositionSet", "1"), path, f"{where}.PositionSet")
    T = None if pose is None or position_set == 0 or not np.any(pose[3:]) else \
        pose_from_survive(pose)
    variance = _floats(group, "variance", 6, path, where)
    if variance is not None and np.any(variance < 0):
        raise InputError("'variance' must not be negative", path, f"{where}.variance")
    covariance = None if T is None or variance is None or not np.any(variance) else \
        covariance_from_survive(T, variance)
    mode = _integer(group.get("mode", "0"), path, f"{where}.mode")
    calibration = None
    if _integer(group.get("OOTXSet", "0"), path, f"{where}.OOTXSet"):
        keys = CALIBRATION_KEYS + (LH2_CALIBRATION_KEYS if generation == 2 else ())
        values = {}
        for key in keys:
            found = _floats(group, SURVIVE_KEYS[key], 2, path, where)
            values[key] = np.zeros(2) if found is None else found
        accel = _floats(group, "accel", 3, path, where)
        accel = np.zeros(3) if accel is None else accel
        check_ranges(values | {"accel_dir": accel}, path, where)
        station_id = _integer(group.get("id", "0"), path, f"{where}.id") & 0xFFFFFFFF
        channel = mode + 1 if generation == 2 and 0 <= mode < 16 else None
        calibration = StationCalibration(FactoryCalibration(**values), station_id, accel,
                                         generation, channel)
    return SurviveLighthouse(T, covariance, calibration, mode)


def read_survive_config(path: str | Path) -> SurviveConfig:
    """Read a libsurvive ``config.json`` (its own files or strict JSON); InputError (one
    line naming the file and the key) on anything libsurvive would misread. Stations
    without a pose are named in ``notes``."""
    path = Path(path)
    raw = read_input(path, "a libsurvive config.json")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError("not a text file", path) from None
    members = parse_survive_text(text, path)
    groups = {}
    for key, value in members.items():
        found = re.fullmatch(r"lighthouse(\d+)", key)
        if found:
            if not isinstance(value, dict):
                raise InputError("must be a {...} group", path, key)
            groups[int(found.group(1))] = value
    if not groups:
        raise InputError('no "lighthouseN" groups: not a libsurvive config with stations',
                         path)
    generation, notes = _generation(members, groups, path)
    lighthouses = {index: _lighthouse(groups[index], index, generation, path)
                   for index in sorted(groups)}
    notes += [f"lighthouse{k} has no pose (PositionSet 0)"
              for k, lh in lighthouses.items() if lh.T_world_lh is None]
    return SurviveConfig(generation, lighthouses, tuple(notes))


def _value(x: float | int) -> str:
    """A quoted libsurvive value: integers as base-10, floats always with a '.' or an
    exponent (libsurvive takes a value that reads fully as an integer for an integer)."""
    if isinstance(x, (int, np.integer)):
        return f'"{int(x)}"'
    text = repr(float(x))
    return f'"{text}"'


def _array(values: list[float]) -> str:
    return "[" + ",".join(_value(float(v)) for v in values) + "]"


def survive_config_text(config: SurviveConfig) -> str:
    """The text of ``config`` laid out as libsurvive writes it (InputError: a non-finite
    value, an id that is not 32-bit)."""
    lines = [f'"{GENERATION_KEY}":"{config.generation}"',
             f'"lighthousecount":"{len(config.lighthouses)}"']
    out = ",\n".join(lines) + "\n"
    for index in sorted(config.lighthouses):
        lh = config.lighthouses[index]
        where = f"station {index}"
        if lh.T_world_lh is None:
            raise InputError("no pose to write", None, where)
        pose = pose_to_survive(lh.T_world_lh)
        variance = [0.0] * 6 if lh.covariance is None else variance_to_survive(
            lh.T_world_lh, lh.covariance)
        if not all(math.isfinite(x) for x in pose + variance):
            raise InputError("a pose or variance that is not finite", None, where)
        c = lh.calibration
        if c is not None and not 0 <= c.id < 2**32:
            raise InputError(f"id {c.id} is not a 32-bit station id", None, where)
        station_id = 0 if c is None else (c.id - 2**32 if c.id >= 2**31 else c.id)
        cal = FactoryCalibration() if c is None else c.calibration
        accel = np.zeros(3) if c is None else c.accel_dir
        members = [f'"index":{_value(index)}', f'"id":{_value(station_id)}',
                   f'"mode":{_value(lh.mode)}', f'"pose":{_array(pose)}',
                   f'"variance":{_array(variance)}', f'"accel":{_array(list(accel))}']
        members += [f'"{key}":{_array(list(getattr(cal, ours)))}'
                    for ours, key in SURVIVE_KEYS.items()]
        members += [f'"OOTXSet":{_value(int(c is not None))}', '"PositionSet":"1"']
        out += f'"lighthouse{index}":{{\n' + ",\n".join(members) + "\n}\n"
    return out


def write_survive_config(config: SurviveConfig, path: str | Path, overwrite: bool = False
                         ) -> Path:
    """Write ``config`` as a libsurvive ``config.json`` (atomically)."""
    return write_atomic(path, survive_config_text(config).encode(), overwrite)
