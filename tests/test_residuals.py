"""Graph residuals: analytic vs numerical Jacobians, and the GTSAM factors built on them."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from lhgraph.estimation.residuals import (
    BearingHits,
    bearing_residuals,
    motion_residuals,
    right_jacobian_inverse,
    wnoa_covariance,
)
from lhgraph.geometry.transforms import se3_exp
from lhgraph.model.station import FactoryCalibration, StationModel

EPS = 1e-6


def _numerical(f, dim=6):
    return np.stack([(f(d) - f(-d)) / (2 * EPS) for d in np.eye(dim) * EPS], axis=-1)


@pytest.fixture()
def scene():
    rng = np.random.default_rng(3)
    K, S, N = 5, 2, 60
    X = se3_exp(rng.normal(size=(K, 6)) * 0.3)
    X[:, 0, 3] += 3.0
    V = rng.normal(size=(K, 6)) * np.r_[3, 3, 3, 2, 2, 2]
    Lh = se3_exp(rng.normal(size=(S, 6)) * 0.1)
    hits = BearingHits(rng.integers(0, K, N), rng.integers(0, S, N),
                       rng.normal(size=(N, 3)) * 0.06, rng.integers(0, 2, N),
                       rng.uniform(-2e-4, 2e-4, N), rng.normal(size=N) * 1e-3)
    cal = FactoryCalibration(phase=[0.01, 0.02], tilt=[0.01, -0.01], curve=[0.002, 0.001],
                             gibphase=[1, 2], gibmag=[0.003, 0.004])
    return X, V, Lh, hits, [StationModel(cal), StationModel()]


def test_bearing_jacobians(scene):
    X, V, Lh, hits, models = scene
    K, S = len(X), len(Lh)
    r, HX, HV, HL = bearing_residuals(hits, X, V, Lh, models)

    def res(X_, V_, L_):
        return bearing_residuals(hits, X_, V_, L_, models, jacobians=False)[0]

    # each hit depends on one state and one station: perturbing all at once is enough
    nX = _numerical(lambda d: res(X @ se3_exp(np.tile(d, (K, 1))), V, Lh))
    nV = _numerical(lambda d: res(X, V + d, Lh))
    nL = _numerical(lambda d: res(X, V, Lh @ se3_exp(np.tile(d, (S, 1)))))
    np.testing.assert_allclose(HX, nX, atol=1e-7)
    np.testing.assert_allclose(HV, nV, atol=1e-7)
    np.testing.assert_allclose(HL, nL, atol=1e-7)


def test_velocity_propagates_hits():
    """A hit dt after the state time sees the board moved by dt * v."""
    X = np.eye(4)[None].copy()
    X[0, 0, 3] = 3.0
    V = np.array([[0, 0, 0, 0, 1.0, 0]])  # 1 m/s along the board's y = station's +y
    hits = BearingHits(np.array([0]), np.array([0]), np.zeros((1, 3)), np.array([0]),
                       np.array([0.003]), np.array([0.0]))
    r, *_ = bearing_residuals(hits, X, V, np.eye(4)[None], [StationModel()])
    assert r[0] == pytest.approx(np.arctan2(0.003, 3.0), rel=1e-12)


def test_motion_jacobians_and_zero_for_constant_velocity():
    rng = np.random.default_rng(4)
    K = 6
    X = se3_exp(rng.normal(size=(K, 6)))
    V = rng.normal(size=(K, 6)) * 2
    dt = np.full(K - 1, 8.3e-3)
    X1 = X[:-1] @ se3_exp(dt[:, None] * V[:-1] + rng.normal(size=(K - 1, 6)) * 1e-2)
    e, (H0, HV0, H1, HV1) = motion_residuals(X[:-1], V[:-1], X1, V[1:], dt)
    n = K - 1

    def res(a, b, c, d):
        return motion_residuals(a, b, c, d, dt, jacobians=False)[0]

    np.testing.assert_allclose(H0, _numerical(lambda d: res(X[:-1] @ se3_exp(np.tile(d, (n, 1))),
                                                            V[:-1], X1, V[1:])), atol=1e-7)
    np.testing.assert_allclose(H1, _numerical(lambda d: res(X[:-1], V[:-1],
                                                            X1 @ se3_exp(np.tile(d, (n, 1))),
                                                            V[1:])), atol=1e-7)
    np.testing.assert_allclose(HV0, _numerical(lambda d: res(X[:-1], V[:-1] + d, X1, V[1:])),
                               atol=1e-7)
    np.testing.assert_allclose(HV1, _numerical(lambda d: res(X[:-1], V[:-1], X1, V[1:] + d)),
                               atol=1e-7)
    # exact constant velocity: zero residual
    Xc = X[:-1] @ se3_exp(dt[:, None] * V[:-1])
    e0, _ = motion_residuals(X[:-1], V[:-1], Xc, V[:-1], dt, jacobians=False)
    np.testing.assert_allclose(e0, 0.0, atol=1e-12)


def test_logmap_derivative_series_matches_gtsam():
    xi = np.array([0.004, -0.003, 0.002, 0.001, 0.003, -0.002])
    xi = xi * 10  # |xi| ~ 0.07, more than one 8 ms step moves: series error ~ |xi|^5
    np.testing.assert_allclose(right_jacobian_inverse(xi), gtsam.Pose3.LogmapDerivative(xi),
                               atol=2e-8)


def test_wnoa_covariance_is_positive_definite():
    Q = wnoa_covariance(np.array([8.3e-3, 1e-3]), 100.0, 10.0)
    assert np.all(np.linalg.eigvalsh(Q) > 0)
    np.testing.assert_allclose(Q[0, 6, 6], 100.0 * 8.3e-3)


def test_scalar_huber_downweights_only_the_outlier():
    """gtsam's Scalar reweighting weights each diode; the default Block would weight all."""
    sigma = 1e-4
    r = np.array([1e-5, -2e-5, 5e-3])  # last diode is a reflection
    H = np.ones((3, 6))
    key = gtsam.symbol_shorthand.X(0)

    def error(_f, _values, jac):
        if jac is not None:
            jac[0] = H
        return r

    values = gtsam.Values()
    values.insert(key, gtsam.Pose3())
    rows = {}
    for scheme in ("Scalar", "Block"):
        huber = gtsam.noiseModel.mEstimator.Huber.Create(
            3.0, getattr(gtsam.noiseModel.mEstimator.Base.ReweightScheme, scheme))
        noise = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Isotropic.Sigma(3, sigma))
        A, _ = gtsam.CustomFactor(noise, [key], error).linearize(values).jacobian()
        rows[scheme] = A[:, 0]
    np.testing.assert_allclose(rows["Scalar"][:2], 1 / sigma)
    assert rows["Scalar"][2] == pytest.approx(np.sqrt(3.0 / 50.0) / sigma)
    assert rows["Block"][0] < 0.5 / sigma  # Block drags the good diodes down too
