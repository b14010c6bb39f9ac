"""Paper-style calibration errors between two station sets (SPEC §4)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lhgraph.geometry.transforms import euler_zyx, rotation_angle
from lhgraph.io.stations import Stations


@dataclass(frozen=True)
class PoseError:
    """Error of one non-reference station, in the reference station's frame.

    ``position_m`` = |p_est - p_true| per axis (m); ``euler_rad`` = |roll, pitch, yaw| of
    ``R_true^T R_est`` (ZYX); norms in m and rad.
    """

    station: int
    position_m: np.ndarray
    euler_rad: np.ndarray
    position_norm_m: float
    rotation_rad: float

    def row_mm_deg(self) -> list[float]:
        """``[X, Y, Z (mm), alpha, beta, gamma (deg), |p| (mm), angle (deg)]``."""
        return [*(self.position_m * 1e3), *np.degrees(self.euler_rad),
                self.position_norm_m * 1e3, float(np.degrees(self.rotation_rad))]


def station_errors(truth: Stations, estimate: Stations) -> list[PoseError]:
    """Errors of every station but the estimate's reference, present in both sets.

    Both sets are re-expressed in the frame of the estimate's reference station, so a truth
    given in any world frame (or with another reference) compares correctly.
    """
    ref = estimate.reference
    t = Stations(ref, truth.stations).relative_to_reference()
    e = estimate.relative_to_reference()
    out = []
    for k in t.indices():
        if k == ref or k not in e.stations:
            continue
        Tt, Te = t.pose(k), e.pose(k)
        dp = np.abs(Te[:3, 3] - Tt[:3, 3])
        dR = Tt[:3, :3].T @ Te[:3, :3]
        out.append(PoseError(k, dp, np.abs(euler_zyx(dR)), float(np.linalg.norm(dp)),
                             float(rotation_angle(dR))))
    return out
