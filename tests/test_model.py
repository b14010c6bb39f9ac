"""Measurement model: known answers, analytic vs numerical Jacobians, inverse round trip."""

from __future__ import annotations

import numpy as np
import pytest

from lhgraph.geometry.transforms import se3_exp
from lhgraph.model.station import (
    Convention,
    FactoryCalibration,
    StationModel,
    ideal_angles,
    ideal_from_measured,
    predict,
    sweep_angle,
)

CAL = FactoryCalibration(phase=[0.05, -0.03], tilt=[0.01, -0.02], curve=[0.003, -0.004],
                         gibphase=[2.9, 0.02], gibmag=[0.005, -0.004])
MODELS = [
    StationModel(),
    StationModel(CAL),
    StationModel(CAL, rotor_offsets=[[0.01, 0.02, -0.01], [-0.01, 0.0, 0.02]],
                 convention=Convention(gib_sign=-1.0, curve_sign=-1.0)),
]


def test_ideal_angles_known_answers():
    p = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 1.0], [2.0, -2.0, 2.0]])
    a = ideal_angles(p)
    np.testing.assert_allclose(a, [[0, 0], [np.pi / 4, 0], [0, np.pi / 4],
                                   [-np.pi / 4, np.pi / 4]], atol=1e-15)
    # +y (left) is positive azimuth, +z (up) positive elevation
    assert sweep_angle([[3.0, 0.5, 0.0]], [0])[0] > 0
    assert sweep_angle([[3.0, 0.0, 0.5]], [1])[0] > 0


def test_factory_terms_match_spec_formula():
    p = np.array([[2.0, 0.4, -0.3]])
    x, y, z = p[0]
    t0 = np.arctan2(y, x) - CAL.phase[0] - np.arcsin(np.tan(CAL.tilt[0]) * z / np.hypot(x, y))
    a0 = t0 + CAL.gibmag[0] * np.sin(CAL.gibphase[0] + t0) + CAL.curve[0] * np.arctan2(z, x) ** 2
    t1 = np.arctan2(z, x) - CAL.phase[1] + np.arcsin(np.tan(CAL.tilt[1]) * y / np.hypot(x, z))
    a1 = t1 + CAL.gibmag[1] * np.sin(CAL.gibphase[1] + t1) + CAL.curve[1] * np.arctan2(y, x) ** 2
    m = StationModel(CAL, convention=Convention(gib_sign=1.0, curve_sign=1.0))
    assert sweep_angle(p, [0], m)[0] == pytest.approx(a0, abs=1e-15)
    assert sweep_angle(p, [1], m)[0] == pytest.approx(a1, abs=1e-15)
    flipped = StationModel(CAL)  # the default, settled on real data: gib -1, curve +1
    assert flipped.convention == Convention(gib_sign=-1.0, curve_sign=1.0)
    expected = t0 - CAL.gibmag[0] * np.sin(CAL.gibphase[0] + t0) + CAL.curve[0] * np.arctan2(
        z, x) ** 2
    assert sweep_angle(p, [0], flipped)[0] == pytest.approx(expected, abs=1e-15)


def test_rotor_offset_shifts_the_origin():
    m = StationModel(rotor_offsets=[[0.0, 0.1, 0.0], [0.0, 0.0, -0.05]])
    p = np.array([[2.0, 0.1, 0.0], [2.0, 0.0, -0.05]])
    np.testing.assert_allclose(sweep_angle(p, [0, 1], m), [0.0, 0.0], atol=1e-15)


@pytest.mark.parametrize("model", MODELS)
def test_point_jacobian_matches_numerical(model):
    rng = np.random.default_rng(1)
    n = 40
    p = np.c_[rng.uniform(1, 5, n), rng.uniform(-2, 2, n), rng.uniform(-2, 2, n)]
    axis = rng.integers(0, 2, n)
    _, J = sweep_angle(p, axis, model, jacobian=True)
    eps = 1e-6
    Jn = np.stack([(sweep_angle(p + eps * e, axis, model) - sweep_angle(p - eps * e, axis, model))
                   / (2 * eps) for e in np.eye(3)], axis=-1)
    np.testing.assert_allclose(J, Jn, atol=1e-8)


@pytest.mark.parametrize("model", MODELS)
def test_pose_jacobians_match_numerical(model):
    rng = np.random.default_rng(2)
    n = 30
    T_lh = se3_exp(rng.normal(size=6) * 0.3)
    T_b = se3_exp(rng.normal(size=(n, 6)) * 0.3)
    T_b[:, 0, 3] += 3.0
    s = rng.normal(size=(n, 3)) * 0.06
    axis = rng.integers(0, 2, n)
    _, H_lh, H_b = predict(T_lh, T_b, s, axis, model, jacobians=True)
    eps = 1e-6
    num_lh, num_b = np.zeros_like(H_lh), np.zeros_like(H_b)
    for i, d in enumerate(np.eye(6) * eps):
        num_lh[:, i] = (predict(T_lh @ se3_exp(d), T_b, s, axis, model)
                        - predict(T_lh @ se3_exp(-d), T_b, s, axis, model)) / (2 * eps)
        num_b[:, i] = (predict(T_lh, T_b @ se3_exp(d), s, axis, model)
                       - predict(T_lh, T_b @ se3_exp(-d), s, axis, model)) / (2 * eps)
    np.testing.assert_allclose(H_lh, num_lh, atol=1e-8)
    np.testing.assert_allclose(H_b, num_b, atol=1e-8)


def test_jacobians_match_gtsam_transform_to():
    """The station-pose Jacobian agrees with GTSAM's own Pose3.transformTo derivative."""
    gtsam = pytest.importorskip("gtsam")
    rng = np.random.default_rng(3)
    T_lh = se3_exp(rng.normal(size=6) * 0.3)
    p_world = np.array([3.0, 0.4, -0.2])
    H = np.zeros((3, 6), order="F")
    q = gtsam.Pose3(T_lh).transformTo(p_world, H)
    _, J = sweep_angle(q[None], [0], jacobian=True)
    _, H_lh, _ = predict(T_lh, np.eye(4), p_world[None], [0], jacobians=True)
    np.testing.assert_allclose(H_lh[0], J[0] @ H, atol=1e-12)


def test_inverse_round_trip():
    rng = np.random.default_rng(4)
    az = rng.uniform(-1.0, 1.0, 200)
    el = rng.uniform(-0.8, 0.8, 200)
    d = np.c_[np.ones_like(az), np.tan(az), np.tan(el)]
    model = StationModel(CAL)
    m_az = sweep_angle(d, np.zeros(200, int), model)
    m_el = sweep_angle(d, np.ones(200, int), model)
    assert np.max(np.abs(m_az - az)) > 1e-2  # the distortion is real
    back_az, back_el = ideal_from_measured(m_az, m_el, model)
    np.testing.assert_allclose(back_az, az, atol=1e-12)
    np.testing.assert_allclose(back_el, el, atol=1e-12)
