"""Station layouts for simulation: where the stations stand and where the board is waved.

A :class:`Scene` is always expressed in the reference station's frame (station 0 = world,
SPEC §4). It is built either from explicit station poses in any "site" frame
(:func:`scene_from_poses`) or from a few numbers (:class:`ParametricLayout`,
:func:`parametric_scene`) describing two stations in a room with z up:

- the stations stand ``baseline_m`` apart on the room's x axis (station 0 at
  ``x = -baseline/2``), at heights ``station_heights_m``;
- the board's motion centre is on the perpendicular bisector, at horizontal distance
  ``distance_m`` from each station and at height ``board_height_m``;
- each station is turned toward the bisector so that the two headings differ by
  ``relative_yaw_deg`` (default: both aim exactly at the motion centre), and pitched down by
  ``pitch_deg`` (default: aimed at the motion centre's height). No roll.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import inverse, make_pose, transform_points

MAX_AIM_OFFSET_DEG = 40.0


@dataclass(frozen=True)
class Scene:
    """Stations ``T_world_lh`` (n, 4, 4), motion centre (3,) and unit ``up`` (3,), world frame."""

    T_world_lh: NDArray[np.float64]
    centre: NDArray[np.float64]
    up: NDArray[np.float64]


@dataclass(frozen=True)
class ParametricLayout:
    """Two stations and a board in a room (see module docstring); lengths m, angles deg."""

    baseline_m: float = 2.0
    distance_m: float = 2.5
    relative_yaw_deg: float | None = None
    station_heights_m: tuple[float, float] = (2.0, 2.0)
    board_height_m: float = 1.2
    pitch_deg: tuple[float, float] | None = None


def _rot_z(a: float) -> NDArray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(a: float) -> NDArray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def scene_from_poses(T_site_lh: ArrayLike, centre_site: ArrayLike, up_site: ArrayLike) -> Scene:
    """Re-express site-frame station poses, motion centre and up vector in station 0's frame."""
    T_site_lh = np.asarray(T_site_lh, dtype=float)
    T_world_site = inverse(T_site_lh[0])
    up = T_world_site[:3, :3] @ np.asarray(up_site, dtype=float)
    return Scene(T_world_site @ T_site_lh, transform_points(T_world_site, centre_site),
                 up / np.linalg.norm(up))


def parametric_scene(layout: ParametricLayout) -> Scene:
    """The scene of a :class:`ParametricLayout`, in station 0's frame.

    Raises InputError (``where`` = the offending key) when the board is not in front of the
    stations: distance below half the baseline, or a station aimed more than
    ``MAX_AIM_OFFSET_DEG`` away from the motion centre.
    """
    b, d = layout.baseline_m, layout.distance_m
    if b <= 0:
        raise InputError(f"must be > 0, got {b}", where="layout.baseline_m")
    if d <= b / 2:
        raise InputError(f"must exceed half the baseline ({b / 2:g} m), got {d}",
                         where="layout.distance_m")
    depth = np.sqrt(d * d - b * b / 4)
    natural_deg = np.degrees(2 * np.arctan2(b / 2, depth))
    yaw_deg = natural_deg if layout.relative_yaw_deg is None else layout.relative_yaw_deg
    offset = (natural_deg - yaw_deg) / 2
    if abs(offset) > MAX_AIM_OFFSET_DEG:
        raise InputError(
            f"{yaw_deg:g} deg aims the stations {abs(offset):.0f} deg away from the board "
            f"(natural value {natural_deg:.1f} deg for this baseline and distance)",
            where="layout.relative_yaw_deg")
    centre = np.array([0.0, depth, layout.board_height_m])
    poses = []
    for i, side in enumerate((-1.0, 1.0)):
        position = np.array([side * b / 2, 0.0, layout.station_heights_m[i]])
        # heading measured from the bisector (+y), turned toward it by half the yaw
        heading = np.pi / 2 + side * np.radians(yaw_deg) / 2
        if layout.pitch_deg is None:
            pitch = np.arctan2(position[2] - centre[2], d)
        else:
            pitch = np.radians(layout.pitch_deg[i])
        poses.append(make_pose(_rot_z(heading) @ _rot_y(pitch), position))
    return scene_from_poses(np.stack(poses), centre, [0.0, 0.0, 1.0])
