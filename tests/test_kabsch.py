"""Weighted Kabsch superposition: exact recovery, weights, reflections, bad input."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lhgraph.geometry.kabsch import weighted_kabsch
from lhgraph.geometry.transforms import make_pose, so3_exp, transform_points


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    return make_pose(so3_exp(rng.normal(size=3) * 1.5), rng.normal(size=3) * 3.0)


@pytest.mark.parametrize("seed", range(5))
def test_noise_free_exact_recovery(seed):
    rng = np.random.default_rng(seed)
    T = _random_pose(rng)
    src = rng.normal(size=(20, 3))
    dst = transform_points(T, src)
    np.testing.assert_allclose(weighted_kabsch(src, dst), T, atol=1e-9)
    w = rng.uniform(0.1, 5.0, len(src))
    np.testing.assert_allclose(weighted_kabsch(src, dst, w), T, atol=1e-9)


def test_coplanar_points_give_a_proper_rotation():
    # Three or more coplanar points: the plain SVD solution can be a reflection.
    rng = np.random.default_rng(7)
    T = _random_pose(rng)
    src = np.c_[rng.normal(size=(12, 2)), np.zeros(12)]
    T_est = weighted_kabsch(src, transform_points(T, src))
    np.testing.assert_allclose(T_est, T, atol=1e-9)
    assert np.linalg.det(T_est[:3, :3]) == pytest.approx(1.0)


def test_zero_weight_ignores_an_outlier_and_weights_matter():
    rng = np.random.default_rng(3)
    T = _random_pose(rng)
    src = rng.normal(size=(15, 3))
    dst = transform_points(T, src)
    dst[4] += [0.5, -0.3, 0.2]
    w = np.ones(len(src))
    w[4] = 0.0
    np.testing.assert_allclose(weighted_kabsch(src, dst, w), T, atol=1e-9)
    assert np.abs(weighted_kabsch(src, dst) - T).max() > 1e-3


def test_reflected_target_gives_the_best_proper_rotation():
    # dst is a mirror image of src: no rotation fits exactly; the answer must be the best
    # proper rotation (checked against scipy's independent solver) with det +1.
    rng = np.random.default_rng(11)
    src = rng.normal(size=(30, 3)) * [3.0, 2.0, 1.0]
    dst = src * [1.0, 1.0, -1.0] + [0.1, 0.2, 0.3]
    w = rng.uniform(0.5, 2.0, len(src))
    T = weighted_kabsch(src, dst, w)
    R = T[:3, :3]
    assert np.linalg.det(R) == pytest.approx(1.0)
    c_src = np.average(src, axis=0, weights=w)
    c_dst = np.average(dst, axis=0, weights=w)
    ref, _ = Rotation.align_vectors(dst - c_dst, src - c_src, weights=w)
    np.testing.assert_allclose(R, ref.as_matrix(), atol=1e-9)
    np.testing.assert_allclose(T[:3, 3], c_dst - R @ c_src, atol=1e-9)


def test_bad_input():
    src = np.zeros((4, 3))
    with pytest.raises(ValueError):
        weighted_kabsch(src, np.zeros((5, 3)))
    with pytest.raises(ValueError):
        weighted_kabsch(src, src, [1.0, -1.0, 1.0, 1.0])
    with pytest.raises(ValueError):
        weighted_kabsch(src, src, np.zeros(4))
