"""SE(3) helpers against GTSAM and known answers."""

from __future__ import annotations

import gtsam
import numpy as np

from lhgraph.geometry.transforms import (
    euler_zyx,
    interpolate_poses,
    inverse,
    matrix_to_quat,
    pose_from_quat,
    rotation_angle,
    se3_exp,
    se3_log,
    so3_exp,
)


def test_exp_log_match_gtsam():
    rng = np.random.default_rng(0)
    for xi in rng.normal(size=(20, 6)):
        T = se3_exp(xi)
        np.testing.assert_allclose(T, gtsam.Pose3.Expmap(xi).matrix(), atol=1e-12)
        np.testing.assert_allclose(se3_log(T), xi, atol=1e-10)
    np.testing.assert_allclose(se3_exp(np.zeros(6)), np.eye(4))


def test_log_matches_gtsam_at_small_and_near_pi_angles():
    rng = np.random.default_rng(1)
    axes = rng.normal(size=(6, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    for angle in (0.0, 1e-9, 1e-5, 1e-4 * 0.99, 1e-4 * 1.01, 0.5, np.pi - 2e-3, np.pi - 1e-6):
        xi = np.concatenate([axes * angle, rng.normal(size=(6, 3))], axis=1)
        T = se3_exp(xi)
        expected = np.array([gtsam.Pose3.Logmap(gtsam.Pose3(t)) for t in T])
        np.testing.assert_allclose(se3_log(T), expected, atol=1e-7)
        np.testing.assert_allclose(se3_exp(se3_log(T)), T, atol=1e-9)


def test_inverse_and_quaternions():
    rng = np.random.default_rng(1)
    T = se3_exp(rng.normal(size=(5, 6)))
    np.testing.assert_allclose(T @ inverse(T), np.broadcast_to(np.eye(4), T.shape), atol=1e-12)
    q = matrix_to_quat(T[:, :3, :3])
    assert np.all(q[:, 0] >= 0)
    np.testing.assert_allclose(pose_from_quat(T[:, :3, 3], q), T, atol=1e-12)
    # a 90 degree yaw: w = cos 45, z = sin 45
    np.testing.assert_allclose(matrix_to_quat(so3_exp([0, 0, np.pi / 2])),
                               [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-12)


def test_euler_zyx_and_angle():
    R = so3_exp([0, 0, 0.3]) @ so3_exp([0, 0.2, 0]) @ so3_exp([0.1, 0, 0])
    np.testing.assert_allclose(euler_zyx(R), [0.1, 0.2, 0.3], atol=1e-12)
    assert np.isclose(rotation_angle(so3_exp([0.0, 0.4, 0.0])), 0.4)


def test_interpolation_midpoint_and_clamping():
    T0 = np.eye(4)
    T1 = se3_exp([0, 0, 1.0, 2.0, 0, 0])
    T1[:3, 3] = [2.0, 0.0, 0.0]
    T = interpolate_poses([0.0, 1.0], np.stack([T0, T1]), [-1.0, 0.5, 2.0])
    np.testing.assert_allclose(T[0], T0, atol=1e-12)
    np.testing.assert_allclose(T[2], T1, atol=1e-12)
    np.testing.assert_allclose(T[1][:3, 3], [1.0, 0, 0], atol=1e-12)
    assert np.isclose(rotation_angle(T[1][:3, :3]), 0.5)
