"""A gravity-aligned world from the stations' OOTX accelerometer vectors.

Every LH1 station broadcasts ``accel_dir`` (int8 x3, OOTX): its accelerometer at rest, i.e.
the station's *up* direction (an accelerometer reads the reaction to gravity), in the
station's native frame (x right, y up, z backward: libsurvive's lighthouse frame). In our
station frame (+x forward, +y left, +z up, SPEC §4) that is

    up = (-a_z, -a_x, a_y) / |a|

Verified on the libsurvive recording (docs/model.md, "Gravity"): with our solved relative
rotation the two stations' vectors agree within 0.5 deg, and of the 24 axis mappings only
this one matches libsurvive's own station frames.

The gravity world keeps the reference station's origin; its +z is up (the mean of the
stations' up vectors, carried into the world by their solved rotations) and its +x is the
reference station's forward axis made horizontal. A solve with the receiver's IMU
(``SolveResult.gravity_world``) observes up itself: :func:`imu_up` turns it into an up
vector of the reference station, and :func:`up_angle_deg` says how far it is from the
stations' OOTX vectors.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.errors import InputError
from lhgraph.estimation.result import SolveResult
from lhgraph.io.stations import Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.calibration import StationCalibration

Array = NDArray[np.float64]

# stations whose up vectors disagree by more than this (deg) get a warning
MAX_SPREAD_DEG = 2.0


def up_in_station(accel_dir: ArrayLike) -> Array:
    """Unit up vector in our station frame from an OOTX ``accel_dir`` (native frame)."""
    a = np.asarray(accel_dir, dtype=float)
    up = np.array([-a[2], -a[0], a[1]])
    norm = np.linalg.norm(up)
    if norm == 0.0:
        raise InputError("accel_dir is [0, 0, 0]: the station sent no accelerometer vector")
    return up / norm


def accel_dir_from_up(up: ArrayLike) -> Array:
    """The OOTX ``accel_dir`` (int8 values, native frame, as floats) of an up vector given in
    our station frame: the inverse of :func:`up_in_station`, scaled to 127."""
    u = np.asarray(up, dtype=float)
    u = u / np.linalg.norm(u)
    return np.round(127.0 * np.array([-u[1], u[2], -u[0]]))


def up_vectors(calibrations: dict[int, StationCalibration]) -> dict[int, Array]:
    """Up vectors (station frame) of the stations whose OOTX holds an accelerometer vector."""
    return {k: up_in_station(c.accel_dir) for k, c in calibrations.items()
            if np.any(c.accel_dir)}


def imu_up(result: SolveResult) -> dict[int, Array]:
    """The up direction the receiver's IMU observed (``result.gravity_world``), as the
    reference station's up vector in its station frame (the form :func:`to_gravity_world`
    takes)."""
    if result.gravity_world is None:
        raise InputError("the solve has no IMU gravity estimate")
    up_world = -result.gravity_world / np.linalg.norm(result.gravity_world)
    ref = result.stations.reference
    return {ref: result.stations.pose(ref)[:3, :3].T @ up_world}


def world_up(stations: Stations, up: dict[int, Array]) -> tuple[Array, float]:
    """The mean up direction (unit, world of ``stations``) of the stations' up vectors ``up``
    and the largest angle (deg) between one of them and the mean."""
    used = [k for k in stations.indices() if k in up]
    if not used:
        raise InputError("no accelerometer vector (OOTX accel_dir) for any solved station: "
                         "a gravity-aligned world needs the stations' factory calibration "
                         "or the receiver's IMU (--imu)")
    in_world = np.array([stations.pose(k)[:3, :3] @ up[k] for k in used])
    z = in_world.sum(axis=0)
    z /= np.linalg.norm(z)
    return z, float(np.degrees(np.max(np.arccos(np.clip(in_world @ z, -1.0, 1.0)))))


def up_angle_deg(stations: Stations, a: dict[int, Array], b: dict[int, Array]) -> float:
    """Angle (deg) between the mean up directions of two sets of up vectors."""
    za, zb = world_up(stations, a)[0], world_up(stations, b)[0]
    return float(np.degrees(np.arccos(np.clip(za @ zb, -1.0, 1.0))))


def gravity_rotation(stations: Stations, up: dict[int, Array]) -> tuple[Array, float]:
    """``T_gravity_world`` (4x4, a rotation about the world origin) and the largest angle
    (deg) between one station's up vector and their mean, both in the world of ``stations``.
    """
    z, spread = world_up(stations, up)
    R_ref = stations.pose(stations.reference)[:3, :3]
    for axis in (R_ref[:, 0], R_ref[:, 2]):  # forward; up if it looks straight up or down
        x = axis - (axis @ z) * z
        if np.linalg.norm(x) > 1e-6:
            break
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z])
    return T, spread


def to_gravity_world(result: SolveResult, up: dict[int, Array]) -> SolveResult:
    """``result`` re-expressed in the gravity-aligned world (stations, trajectory).

    Covariances are in each station's own tangent space and do not change. Adds
    ``diagnostics["gravity_spread_deg"]``, ``world = "gravity"`` to the stations' extra keys,
    and a warning when the stations' up vectors disagree by more than ``MAX_SPREAD_DEG``.
    """
    T, spread = gravity_rotation(result.stations, up)
    stations = Stations(
        result.stations.reference,
        {k: s.moved(T) for k, s in result.stations.stations.items()},
        {**result.stations.extra, "world": "gravity"},
    )
    trajectory = None
    if result.trajectory is not None:
        trajectory = Trajectory(result.trajectory.time, T @ result.trajectory.T_world_board)
    warnings = list(result.warnings)
    if spread > MAX_SPREAD_DEG:
        warnings.append(f"the stations' accelerometer vectors disagree by up to {spread:.1f} "
                        "deg with the solved rotations (a station moved, or its OOTX is "
                        "stale): the gravity alignment is uncertain by that much")
    gravity = (None if result.gravity_world is None
               else T[:3, :3] @ result.gravity_world)
    return dataclasses.replace(result, stations=stations, trajectory=trajectory,
                               warnings=warnings, gravity_world=gravity,
                               diagnostics={**result.diagnostics, "gravity_spread_deg": spread})
