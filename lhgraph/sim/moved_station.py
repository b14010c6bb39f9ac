"""A capture during which a station is bumped: :func:`moved_station_capture` (what the
moved-station watch, :mod:`lhgraph.estimation.station_watch`, is tested on).

The capture is simulated twice with one seed, so one board motion: once with the stations
of ``config``, once with one of them moved by ``T_delta`` (in its own frame); the hits
before ``t_s`` come from the first, those from ``t_s`` on from the second. The truth is the
first's (the calibration a lab would hold); the moved pose is returned beside it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import matrix_to_quat
from lhgraph.io.angles import Angles
from lhgraph.sim.common import SimulatedCapture, scene_of
from lhgraph.sim.config import SimulationConfig
from lhgraph.sim.simulate import simulate

Array = NDArray[np.float64]


def pose_rows(T_site_lh: Array) -> tuple[tuple[float, ...], ...]:
    """Station poses (n, 4, 4) as a config's ``stations`` rows ``(x, y, z, qw, qx, qy, qz)``."""
    return tuple(tuple(float(v) for v in np.r_[T[:3, 3], matrix_to_quat(T[:3, :3])])
                 for T in T_site_lh)


def moved_station_capture(config: SimulationConfig, station: int, T_delta: Array, t_s: float,
                          seed: int | None = None) -> tuple[SimulatedCapture, Array]:
    """The capture of ``config`` (``seed``) in which station ``station`` (not 0, whose frame
    is the world) moves to ``T_world_lh @ T_delta`` at ``t_s`` (s); and its pose after the
    move ``T_world_lh`` (4, 4). The capture's ``truth`` is the stations before the move."""
    if station == 0:
        raise InputError("station 0's frame is the simulated world: move another station",
                         where="station")
    if not 0 < t_s < config.duration_s:
        raise InputError(f"must be inside the capture (0, {config.duration_s:g}) s, "
                         f"got {t_s:g}", where="t_s")
    scene = scene_of(config)
    if not 0 < station < len(scene.T_world_lh):
        raise InputError(f"no station {station} in a {len(scene.T_world_lh)}-station "
                         "configuration", where="station")
    fixed = replace(config, stations=pose_rows(scene.T_world_lh),
                    motion=replace(config.motion, centre_m=tuple(map(float, scene.centre)),
                                   up=tuple(map(float, scene.up))))
    moved = scene.T_world_lh.copy()
    moved[station] = moved[station] @ T_delta
    before, after = simulate(fixed, seed), simulate(replace(fixed, stations=pose_rows(moved)),
                                                    seed)
    a, b = before.angles.time < t_s, after.angles.time >= t_s
    angles = Angles(*(np.concatenate([getattr(before.angles, c)[a], getattr(after.angles, c)[b]])
                      for c in ("time", "lighthouse", "axis", "sensor", "angle")),
                    extra={k: np.concatenate([v[a], after.angles.extra[k][b]])
                           for k, v in before.angles.extra.items()})
    capture = replace(before, angles=angles,
                      reflected=np.concatenate([before.reflected[a], after.reflected[b]]),
                      pulses=None, slots=None)
    return capture, moved[station]
