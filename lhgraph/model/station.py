"""A base station's measurement model, whatever its generation: station-frame point -> the
angle it measures (pure, vectorised numpy).

Station frame (SPEC §4): +x forward (optical axis), +y left, +z up. A station measures two
angles of a diode, indexed by ``axis`` as in the angles CSV:

- **LH1** (``generation = 1``, :mod:`lhgraph.model.lh1`): axis 0 the azimuth sweep, axis 1
  the elevation sweep, each on its own rotor;
- **LH2** (``generation = 2``, :mod:`lhgraph.model.lh2`): axis 0 and 1 the rotor angles at
  which the first and second light plane (tilted -30° and +30°) cross the diode, one rotor.

:class:`StationModel` holds the generation, the factory calibration (per-axis terms, in our
convention: docs/model.md) and the rotor offsets; :func:`sweep_angle` evaluates it (with the
derivative w.r.t. the point), :func:`predict` from poses (with Jacobians in GTSAM's ``Pose3``
tangent convention: right perturbation ``[omega, v]``), and :func:`ideal_pair_from_measured`
and :func:`ideal_from_measured` invert the calibration for a diode's two angles.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.geometry.transforms import cross
from lhgraph.model import lh1, lh2
from lhgraph.model.factory import (
    CALIBRATION_KEYS,
    LH2_CALIBRATION_KEYS,
    Convention,
    FactoryCalibration,
)

# the calibration terms (lhgraph.model.factory) are part of the station model's API
__all__ = ["CALIBRATION_KEYS", "GENERATIONS", "IDEAL", "LH2_CALIBRATION_KEYS", "Convention",
           "FactoryCalibration", "StationModel", "board_jacobian", "ideal_angles",
           "ideal_from_measured", "ideal_pair_from_measured", "predict", "sensor_in_station",
           "sweep_angle"]

Array = NDArray[np.float64]

GENERATIONS = (1, 2)


@dataclass(frozen=True)
class StationModel:
    """Everything that maps a station-frame point to the two angles of one station:
    ``generation`` (1 or 2), the factory calibration and ``rotor_offsets[k]``, the position
    (m, station frame) of axis k's rotor centre (LH2: one rotor, the same for both); and an
    LH2 station's ``channel`` (1-16: its rotor period, SPEC §8), when known."""

    calibration: FactoryCalibration = field(default_factory=FactoryCalibration)
    rotor_offsets: Array = field(default_factory=lambda: np.zeros((2, 3)))
    convention: Convention = field(default_factory=Convention)
    generation: int = 1
    channel: int | None = None

    def __post_init__(self) -> None:
        offsets = np.asarray(self.rotor_offsets, dtype=float).reshape(2, 3)
        object.__setattr__(self, "rotor_offsets", offsets)
        if self.generation not in GENERATIONS:
            raise ValueError(f"generation must be 1 or 2, got {self.generation!r}")

    def far_field(self) -> StationModel:
        """The same station with its rotor offsets at the origin."""
        return replace(self, rotor_offsets=np.zeros((2, 3)))


IDEAL = StationModel()


def sweep_angle(p_lh: ArrayLike, axis: ArrayLike, model: StationModel = IDEAL, *,
                jacobian: bool = False) -> Array | tuple[Array, Array]:
    """Measured angle (rad) of station-frame points ``(N, 3)`` (m) for ``axis`` ``(N,)``.

    With ``jacobian=True`` also returns ``d angle / d p_lh`` ``(N, 3)``.
    """
    p = np.asarray(p_lh, dtype=float)
    axis = np.asarray(axis, dtype=int)
    q = p - model.rotor_offsets[axis]
    c = model.calibration
    if model.generation == 2:
        return lh2.plane_angle(q, axis, c, jacobian=jacobian)
    return lh1.rotor_angle(q, axis, c, model.convention, jacobian=jacobian)


def ideal_angles(p_lh: ArrayLike, generation: int = 1) -> Array:
    """The ideal station's two angles ``(..., 2)`` (rad) of station-frame points
    ``(..., 3)``: LH1 ``[azimuth, elevation]``, LH2 the two planes' rotor angles."""
    return lh2.ideal_angles(p_lh) if generation == 2 else lh1.ideal_angles(p_lh)


def ideal_pair_from_measured(a0: ArrayLike, a1: ArrayLike, model: StationModel = IDEAL,
                             iterations: int = 8) -> tuple[Array, Array]:
    """Invert the factory calibration of a direction's two measured angles (axis 0 and 1):
    the ideal station's two angles (:func:`ideal_angles` of ``model``'s generation, rad)
    of the direction that ``model`` maps to the measured pair; rotor offsets are ignored
    (far field). Fixed-point iteration: the calibration's terms are small."""
    m0 = np.asarray(a0, dtype=float)
    m1 = np.asarray(a1, dtype=float)
    lh = lh2 if model.generation == 2 else lh1
    far = model.far_field()
    i0, i1 = m0.copy(), m1.copy()
    zeros = np.zeros(m0.size, dtype=int)
    for _ in range(iterations):
        d = lh.direction(i0, i1).reshape(-1, 3)
        i0 = i0 + (m0 - sweep_angle(d, zeros, far).reshape(m0.shape))
        i1 = i1 + (m1 - sweep_angle(d, zeros + 1, far).reshape(m1.shape))
    return i0, i1


def ideal_from_measured(a0: ArrayLike, a1: ArrayLike, model: StationModel = IDEAL,
                        iterations: int = 8) -> tuple[Array, Array]:
    """The ideal LH1 angles ``(azimuth, elevation)`` (rad) of the direction whose measured
    angles (axis 0 and 1) are ``a0, a1`` (:func:`ideal_pair_from_measured`; for LH2 the
    ideal plane angles converted by :func:`lhgraph.model.lh2.lh1_equivalent`). Used by the
    baseline and the initialisers, which work on ideal LH1 angles."""
    i0, i1 = ideal_pair_from_measured(a0, a1, model, iterations)
    return lh2.lh1_equivalent(i0, i1) if model.generation == 2 else (i0, i1)


def _relative_pose(T_world_lh: Array, T_world_board: Array) -> tuple[Array, Array]:
    """Rotation ``(..., 3, 3)`` and translation ``(..., 3)`` of ``T_lh_board``."""
    R_l = np.swapaxes(T_world_lh[..., :3, :3], -1, -2)
    R = R_l @ T_world_board[..., :3, :3]
    t = (R_l @ (T_world_board[..., :3, 3] - T_world_lh[..., :3, 3])[..., None])[..., 0]
    return R, t


def sensor_in_station(T_world_lh: ArrayLike, T_world_board: ArrayLike, s_board: ArrayLike) -> Array:
    """Station-frame position ``(N, 3)`` of board-frame sensor points ``(N, 3)``.

    ``T_world_lh`` and ``T_world_board`` are ``(4, 4)`` or ``(N, 4, 4)``.
    """
    R, t = _relative_pose(np.asarray(T_world_lh, dtype=float),
                          np.asarray(T_world_board, dtype=float))
    s = np.asarray(s_board, dtype=float)
    return (R @ s[..., None])[..., 0] + t


def board_jacobian(J_p: Array, R_lh_board: Array, s_board: Array) -> Array:
    """Derivative ``(..., 6)`` of an angle w.r.t. a right perturbation ``[omega, v]`` of
    ``T_world_board``, from its derivative ``J_p`` ``(..., 3)`` w.r.t. the station-frame point
    ``p = R_lh_board s_board + t``: ``d p / d xi = R_lh_board [-[s]x, I]``, so the result is
    ``[s x J_b, J_b]`` with ``J_b = J_p R_lh_board`` (broadcasting over leading axes)."""
    J_b = (J_p[..., None, :] @ R_lh_board)[..., 0, :]
    return np.concatenate([cross(s_board, J_b), J_b], axis=-1)


def predict(
    T_world_lh: ArrayLike,
    T_world_board: ArrayLike,
    s_board: ArrayLike,
    axis: ArrayLike,
    model: StationModel = IDEAL,
    *,
    jacobians: bool = False,
) -> Array | tuple[Array, Array, Array]:
    """Predicted angles ``(N,)`` of sensors ``s_board`` (board frame, m) seen by one station.

    With ``jacobians=True`` also returns ``H_lh`` and ``H_board`` ``(N, 6)``: the derivatives
    w.r.t. right perturbations ``[omega, v]`` of ``T_world_lh`` and ``T_world_board``.
    """
    R, t = _relative_pose(np.asarray(T_world_lh, dtype=float),
                          np.asarray(T_world_board, dtype=float))
    s = np.asarray(s_board, dtype=float)
    p_lh = (R @ s[..., None])[..., 0] + t
    if not jacobians:
        return sweep_angle(p_lh, axis, model)
    angle, J_p = sweep_angle(p_lh, axis, model, jacobian=True)
    # p_lh = R_l^T (R_b s + t_b - t_l)
    # d p_lh / d xi_lh    = [ [p_lh]x , -I ]       -> J [p]x = J x p
    H_lh = np.concatenate([cross(J_p, p_lh), -J_p], axis=-1)
    return angle, H_lh, board_jacobian(J_p, R, s)
