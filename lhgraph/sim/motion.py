"""Analytic board motions for simulation: smooth hand waving, circles and figure eights.

A :class:`Motion` is a sum of sinusoids on six channels around a mean pose
``(centre, R_mean)``:

    d(t) = sum_m A[:, m] sin(omega[:, m] t + phase[:, m])          (6,)
    T_world_board(t) = [ R_mean Exp(d[3:6]) | centre + R_mean d[0:3] ]

so channels 0-2 are displacements (m) along the mean board axes (x lateral, y "up",
z toward the stations) and channels 3-5 a rotation vector (rad) in the mean board frame.
Poses and velocities are exact at any time, so hit times can be solved on the true motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.geometry.transforms import make_pose, so3_exp

PATTERNS = ("wave", "circle", "figure8")
COMPONENTS = 3  # sinusoids per channel


@dataclass(frozen=True)
class Motion:
    """Mean pose and sinusoid parameters ``amplitude, omega (rad/s), phase`` (6, COMPONENTS)."""

    centre: NDArray[np.float64]
    R_mean: NDArray[np.float64]
    amplitude: NDArray[np.float64]
    omega: NDArray[np.float64]
    phase: NDArray[np.float64]

    def offsets(self, t: ArrayLike) -> NDArray[np.float64]:
        """Channel values ``(N, 6)`` at times ``t`` (N,) (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        arg = t[:, None, None] * self.omega + self.phase
        return np.sum(self.amplitude * np.sin(arg), axis=-1)

    def pose(self, t: ArrayLike) -> NDArray[np.float64]:
        """``T_world_board`` ``(N, 4, 4)`` at times ``t`` (N,) (s)."""
        d = self.offsets(t)
        R = self.R_mean @ so3_exp(d[:, 3:])
        return make_pose(R, self.centre + d[:, :3] @ self.R_mean.T)

    def velocity(self, t: ArrayLike) -> NDArray[np.float64]:
        """World-frame linear velocity (m/s) of the board origin ``(N, 3)`` at times ``t``."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        arg = t[:, None, None] * self.omega[:3] + self.phase[:3]
        v = np.sum(self.amplitude[:3] * self.omega[:3] * np.cos(arg), axis=-1)
        return v @ self.R_mean.T


def facing_rotation(centre: ArrayLike, targets: ArrayLike, up: ArrayLike) -> NDArray[np.float64]:
    """Mean board rotation ``R_world_board``: +z toward the mean direction to ``targets``.

    ``targets`` (n, 3) are the station positions; board +x is horizontal (perpendicular to
    ``up``) and +y completes the frame (pointing up-ish).
    """
    centre = np.asarray(centre, dtype=float)
    to = np.asarray(targets, dtype=float) - centre
    z = np.sum(to / np.linalg.norm(to, axis=1, keepdims=True), axis=0)
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-6:  # looking straight up or down: any horizontal x will do
        x = np.cross([1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _shape(pattern: str, amplitude_m: NDArray, rotation_rad: float,
           rng: np.random.Generator) -> tuple[NDArray, NDArray, NDArray]:
    """Unscaled (amplitude, omega, phase) of a pattern with a base rate of 1 rad/s."""
    amp = np.zeros((6, COMPONENTS))
    omega = np.zeros((6, COMPONENTS))
    phase = rng.uniform(0, 2 * np.pi, (6, COMPONENTS))
    rot_amp = rotation_rad * np.array([1.0, 1.0, 0.5])
    if pattern == "wave":
        weights = rng.uniform(0.3, 1.0, (6, COMPONENTS))
        weights /= weights.sum(axis=1, keepdims=True)
        amp[:] = weights * np.r_[amplitude_m, rot_amp][:, None]
        omega[:] = rng.uniform(0.5, 1.5, (6, COMPONENTS))
        return amp, omega, phase
    start = phase[0, 0]
    if pattern == "circle":
        amp[0:2, 0] = amplitude_m[0:2]
        omega[0:2, 0] = 1.0
        phase[0:2, 0] = [start + np.pi / 2, start]
    else:  # figure8: Lissajous 1:2 in the board's mean plane
        amp[0:2, 0] = amplitude_m[0:2]
        omega[0:2, 0] = [1.0, 2.0]
        phase[0:2, 0] = [start, 2 * start]
    amp[3:, 0] = rot_amp
    omega[3:, 0] = 1.0
    return amp, omega, phase


def make_motion(pattern: str, speed_mps: float, centre: ArrayLike, R_mean: ArrayLike,
                amplitude_m: ArrayLike, rotation_amplitude_rad: float, duration_s: float,
                rng: np.random.Generator) -> Motion:
    """A motion of ``pattern`` whose mean speed over ``[0, duration_s]`` is ``speed_mps``.

    ``amplitude_m`` = half-extents (m) along the mean board x, y, z; ``rotation_amplitude_rad``
    bounds the tilt about board x and y (half of it about z). "wave" is a random sum of
    sinusoids per channel, "circle" an ellipse and "figure8" a 1:2 Lissajous curve in the
    board's mean plane; all three rock the board about its mean orientation.
    """
    if pattern not in PATTERNS:
        raise ValueError(f"unknown motion pattern {pattern!r}")
    amplitude_m = np.asarray(amplitude_m, dtype=float)
    amp, omega, phase = _shape(pattern, amplitude_m, rotation_amplitude_rad, rng)
    motion = Motion(np.asarray(centre, dtype=float), np.asarray(R_mean, dtype=float),
                    amp, omega * 0.0, phase)
    if speed_mps <= 0 or not np.any(amp[:3]):
        return motion
    t = np.arange(0.0, duration_s, 1e-3)
    scale = 1.0
    for _ in range(6):  # mean speed is nearly linear in the time scale: converges fast
        motion = Motion(motion.centre, motion.R_mean, amp, omega * scale, phase)
        mean_speed = float(np.mean(np.linalg.norm(motion.velocity(t), axis=1)))
        scale *= speed_mps / mean_speed
    return Motion(motion.centre, motion.R_mean, amp, omega * scale, phase)
