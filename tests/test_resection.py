"""Resection: the stations' poses from the hits of a receiver whose path is known."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lhgraph.errors import SolverError
from lhgraph.estimation.resection import resect_stations
from lhgraph.geometry.transforms import make_pose, rotation_angle, so3_exp
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIG = Path(__file__).parents[1] / "configs" / "simulation" / "default.toml"
PERTURBATION = make_pose(so3_exp([0.03, -0.04, 0.02]), [0.2, -0.1, 0.15])


@pytest.fixture(scope="module")
def capture():
    """A 10 s simulated board capture; its angles' times are the hit times."""
    return simulate(replace(load_simulation_config(CONFIG), duration_s=10.0), seed=5)


def resected(cap, T_tracked, **options):
    a = cap.angles.select(~cap.reflected)
    models = {k: cap.truth.stations[k].model for k in cap.truth.indices()}
    starts = {k: cap.truth.pose(k) @ PERTURBATION for k in cap.truth.indices()}
    return resect_stations(T_tracked, cap.board.positions[a.sensor], a.lighthouse, a.axis,
                           a.angle, models, starts, **options)


def true_path(cap):
    return cap.trajectory.at(cap.angles.time[~cap.reflected])


def assert_truth(cap, r, position_m=1e-3, rotation_rad=2e-4):
    for k in cap.truth.indices():
        truth = cap.truth.pose(k)
        assert np.linalg.norm(r.T_ref_lh[k][:3, 3] - truth[:3, 3]) < position_m
        assert rotation_angle(r.T_ref_lh[k][:3, :3].T @ truth[:3, :3]) < rotation_rad


def test_resection_recovers_the_stations_from_the_true_path(capture):
    r = resected(capture, true_path(capture))
    assert r.converged and r.iterations < 20
    assert_truth(capture, r)
    assert r.median_abs_residual_rad < 1e-4  # the simulated noise: tens of microradians
    np.testing.assert_array_equal(r.lever_m, 0.0)


def test_resection_gives_the_stations_in_the_paths_frame(capture):
    """A path shifted by 5 cm gives every station shifted by the same 5 cm."""
    shift = make_pose(np.eye(3), [0.05, 0.0, 0.0])
    r = resected(capture, shift @ true_path(capture))
    for k in capture.truth.indices():
        np.testing.assert_allclose(r.T_ref_lh[k][:3, 3] - capture.truth.pose(k)[:3, 3],
                                   [0.05, 0.0, 0.0], atol=1e-3)


def test_resection_solves_the_tracked_points_lever(capture):
    """The path of a point 6 cm off the board's origin: held at zero the lever biases the
    stations; solved, it is found to a millimetre and the stations are right again."""
    lever = np.array([0.03, -0.02, 0.05])
    T = true_path(capture).copy()
    T[:, :3, 3] += T[:, :3, :3] @ lever
    held = resected(capture, T)
    off = max(np.linalg.norm(held.T_ref_lh[k][:3, 3] - capture.truth.pose(k)[:3, 3])
              for k in capture.truth.indices())
    assert off > 5e-3
    solved = resected(capture, T, solve_lever=True)
    assert solved.converged
    np.testing.assert_allclose(solved.lever_m, lever, atol=1e-3)
    assert_truth(capture, solved)


def test_resection_refuses_hits_that_cannot_fix_a_pose(capture):
    T_one = np.broadcast_to(capture.trajectory.at(capture.angles.time[:1]), (8, 4, 4))
    s = np.zeros((8, 3))  # one sensor, one pose: two angles repeated
    models = {0: capture.truth.stations[0].model}
    start = {0: capture.truth.pose(0)}
    axis = np.array([0, 1] * 4)
    with pytest.raises(SolverError, match="do not determine"):
        resect_stations(T_one, s, np.zeros(8), axis, np.zeros(8), models, start)
    with pytest.raises(SolverError, match="at least 6 hits"):
        resect_stations(T_one[:4], s[:4], np.zeros(4), axis[:4], np.zeros(4), models, start)
    with pytest.raises(SolverError, match="no model or start"):
        resect_stations(T_one, s, np.ones(8), axis, np.zeros(8), models, start)
