"""Board trajectories (``*.csv``: ``time,x,y,z,qw,qx,qy,qz``): ``T_world_board`` over time."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import interpolate_poses, matrix_to_quat, pose_from_quat
from lhgraph.io.files import read_csv_columns, write_csv_columns

COLUMNS = tuple((name, float) for name in ("time", "x", "y", "z", "qw", "qx", "qy", "qz"))


@dataclass
class Trajectory:
    """Board poses ``T_world_board`` (N, 4, 4) at increasing ``time`` (N,) (s)."""

    time: NDArray[np.float64]
    T_world_board: NDArray[np.float64]

    def at(self, t: NDArray) -> NDArray[np.float64]:
        """Interpolated poses at times ``t`` (clamped to the ends)."""
        return interpolate_poses(self.time, self.T_world_board, t)


def load_trajectory(path: str | Path) -> Trajectory:
    """Read and validate a trajectory CSV."""
    c = read_csv_columns(path, COLUMNS)
    if len(c["time"]) == 0:
        raise InputError("no rows after the header", path)
    if len(c["time"]) > 1 and np.any(back := np.diff(c["time"]) <= 0):
        raise InputError("time must increase", path, str(int(np.flatnonzero(back)[0]) + 3))
    q = np.stack([c["qw"], c["qx"], c["qy"], c["qz"]], axis=1)
    norm = np.linalg.norm(q, axis=1)
    if np.any(bad := (norm < 0.9) | (norm > 1.1)):
        raise InputError("quaternion norm is not ~1", path, str(int(np.flatnonzero(bad)[0]) + 2))
    p = np.stack([c["x"], c["y"], c["z"]], axis=1)
    return Trajectory(c["time"], pose_from_quat(p, q / norm[:, None]))


def save_trajectory(traj: Trajectory, path: str | Path, overwrite: bool = False,
                    extra: dict[str, NDArray] | None = None) -> Path:
    """Write a trajectory CSV; ``extra`` columns (one value per row) after the contract's."""
    q = matrix_to_quat(traj.T_world_board[:, :3, :3])
    p = traj.T_world_board[:, :3, 3]
    cols = {"time": traj.time, "x": p[:, 0], "y": p[:, 1], "z": p[:, 2],
            "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]}
    fmts = {"time": "{:.9f}", **{k: "{:.10g}" for k in list(cols)[1:]},
            **{k: "{:.6g}" for k in extra or {}}}
    return write_csv_columns(path, cols | dict(extra or {}), fmts, overwrite)
