"""LH2 measurement model: known answers, the LH1-equivalent conversion, analytic vs numerical
Jacobians, the inverse, and the calibration against the real LH2 log's ``correctedAngle``
(skipped without the shared Bitcraze dataset, which is read in place and never copied)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lhgraph.geometry.transforms import se3_exp
from lhgraph.model import lh1, lh2
from lhgraph.model.station import (
    FactoryCalibration,
    StationModel,
    ideal_angles,
    ideal_from_measured,
    ideal_pair_from_measured,
    predict,
    sweep_angle,
)

CAL = FactoryCalibration(phase=[0.0, 0.0032], tilt=[-0.052, 0.0497], gibphase=[2.68, 1.02],
                         gibmag=[-0.004, 0.005])
LH2 = StationModel(CAL, generation=2)
POINTS = np.array([[2.0, 0.4, -0.3], [3.0, -1.0, 0.8], [1.5, 0.2, 0.1], [4.0, 2.5, -1.5]])
LH2_LOG = (Path(__file__).resolve().parents[2] / "shared" / "data" / "bitcraze-positioning"
           / "lh2_crossingBeam_move")


def test_ideal_planes_known_answers():
    # on the horizon both planes cross at the azimuth; above it the first plane (-30°)
    # comes first: alpha_i = az + asin(z tan(t_i) / r)
    a = lh2.ideal_angles([[1.0, 1.0, 0.0], [2.0, 0.0, 1.0]])
    np.testing.assert_allclose(a[0], [np.pi / 4, np.pi / 4], atol=1e-15)
    d = np.arcsin(np.tan(np.pi / 6) / 2)
    np.testing.assert_allclose(a[1], [-d, d], atol=1e-15)
    ideal = StationModel(generation=2)
    np.testing.assert_allclose(sweep_angle(POINTS, np.zeros(4, int), ideal),
                               lh2.ideal_angles(POINTS)[:, 0], atol=1e-15)
    np.testing.assert_allclose(ideal_angles(POINTS, 2), lh2.ideal_angles(POINTS), atol=0)


def test_lh1_equivalent_and_direction_invert_the_planes():
    planes = lh2.ideal_angles(POINTS)
    az, el = lh2.lh1_equivalent(planes[:, 0], planes[:, 1])
    np.testing.assert_allclose(np.c_[az, el], lh1.ideal_angles(POINTS), atol=1e-14)
    d = lh2.direction(planes[:, 0], planes[:, 1])
    np.testing.assert_allclose(d, POINTS / POINTS[:, :1], atol=1e-14)


def test_calibration_formula():
    x, y, z = POINTS.T
    az = np.arctan2(y, x)
    for i, t in enumerate((-np.pi / 6, np.pi / 6)):
        expected = (az + np.arcsin(z * np.tan(t - CAL.tilt[i]) / np.hypot(x, y))
                    - CAL.phase[i] + CAL.gibmag[i] * np.cos(az + CAL.gibphase[i]))
        np.testing.assert_allclose(sweep_angle(POINTS, np.full(4, i), LH2), expected,
                                   atol=1e-15)
    # the LH1 model of the same calibration is another function
    assert not np.allclose(sweep_angle(POINTS, np.zeros(4, int), StationModel(CAL)),
                           sweep_angle(POINTS, np.zeros(4, int), LH2))


@pytest.mark.parametrize("plane", [0, 1])
def test_point_jacobian_matches_numerical(plane):
    model = StationModel(CAL, rotor_offsets=[[0.01, -0.02, 0.03]] * 2, generation=2)
    axis = np.full(len(POINTS), plane)
    _, J = sweep_angle(POINTS, axis, model, jacobian=True)
    h = 1e-7
    for k in range(3):
        dp = np.zeros(3)
        dp[k] = h
        num = (sweep_angle(POINTS + dp, axis, model) - sweep_angle(POINTS - dp, axis, model))
        np.testing.assert_allclose(J[:, k], num / (2 * h), rtol=1e-6, atol=1e-8)


def test_pose_jacobians_match_numerical():
    rng = np.random.default_rng(3)
    T_lh = se3_exp(np.r_[0.1, -0.2, 0.3, 0.5, -0.4, 2.0])
    T_board = se3_exp(np.r_[0.2, 0.1, -0.1, 3.0, 0.3, 1.5])
    s = rng.uniform(-0.05, 0.05, (6, 3))
    axis = np.array([0, 1, 0, 1, 0, 1])
    _, H_lh, H_b = predict(T_lh, T_board, s, axis, LH2, jacobians=True)
    h = 1e-7
    for k in range(6):
        xi = np.zeros(6)
        xi[k] = h
        for H, perturb in ((H_lh, lambda d: (T_lh @ se3_exp(d), T_board)),
                           (H_b, lambda d: (T_lh, T_board @ se3_exp(d)))):
            plus = predict(*perturb(xi), s, axis, LH2)
            minus = predict(*perturb(-xi), s, axis, LH2)
            np.testing.assert_allclose(H[:, k], (plus - minus) / (2 * h), rtol=1e-5,
                                       atol=1e-8)


def test_inverse_round_trip():
    m0 = sweep_angle(POINTS, np.zeros(4, int), LH2)
    m1 = sweep_angle(POINTS, np.ones(4, int), LH2)
    i0, i1 = ideal_pair_from_measured(m0, m1, LH2)
    np.testing.assert_allclose(np.c_[i0, i1], lh2.ideal_angles(POINTS), atol=1e-12)
    az, el = ideal_from_measured(m0, m1, LH2)
    np.testing.assert_allclose(np.c_[az, el], lh1.ideal_angles(POINTS), atol=1e-12)


def firmware_style_correction(m: np.ndarray, model: StationModel) -> np.ndarray:
    """The deck firmware's documented way of correcting a pair: at most 5 fixed-point steps,
    stopped once both corrections are below 5e-4 rad (so its ``correctedAngle`` is not the
    exact inverse)."""
    e = m.copy()
    done = np.zeros(len(m), dtype=bool)
    for _ in range(5):
        d = np.stack([m[:, i] - sweep_angle(lh2.direction(e[:, 0], e[:, 1]),
                                            np.full(len(m), i), model) for i in (0, 1)],
                     axis=1)
        e = np.where(done[:, None], e, e + d)
        done |= np.all(np.abs(d) < 5e-4, axis=1)
    return e


@pytest.mark.skipif(not (LH2_LOG / "log00").is_file(), reason="shared Bitcraze dataset absent")
def test_model_reproduces_the_logs_corrected_angle():
    from lhgraph.importers.crazyflie import read_usd_log
    from lhgraph.io.cfclient import read_system_config

    ev = read_usd_log(LH2_LOG / "log00").events["lhAngle"]
    config = read_system_config(LH2_LOG / "system-config.yaml")
    for bs in (0, 1):
        e = ev[ev["basestation"] == bs]
        # each diode's two planes are logged as consecutive events
        first = np.flatnonzero((e["sweep"][:-1] == 0) & (e["sweep"][1:] == 1)
                               & (e["sensor"][:-1] == e["sensor"][1:]))
        m = np.c_[e["angle"][first], e["angle"][first + 1]].astype(float)
        c = np.c_[e["correctedAngle"][first], e["correctedAngle"][first + 1]].astype(float)
        model = config.calibrations[bs].model()
        assert model.generation == 2 and len(m) > 5000
        # our exact inverse vs the firmware's early-stopped one: tens of µrad
        exact = np.stack(ideal_pair_from_measured(m[:, 0], m[:, 1], model), axis=1)
        assert np.median(np.abs(exact - c)) < 4e-5
        # the firmware's own stopping rule on our model: float32 rounding only
        assert np.max(np.abs(firmware_style_correction(m, model) - c)) < 2e-6
        # without the calibration: ~10 mrad off
        assert np.median(np.abs(m - c)) > 5e-3
