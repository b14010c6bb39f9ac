"""Real data: calibrate from the committed libsurvive fixture (MIT, 6.8 s of a static HMD)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.geometry.transforms import inverse, rotation_angle
from lhgraph.model.board import load_board
from lhgraph.signal.formats import decode_file
from lhgraph.signal.libsurvive import read_libsurvive_board, read_libsurvive_poses
from lhgraph.workflow.inputs import models_of

FIXTURE = Path(__file__).resolve().parent / "data" / "libsurvive" / "lh1_test_cal_hmd_7s.rec.gz"


def test_graph_agrees_with_libsurvive_on_real_data():
    decoded, _ = decode_file(FIXTURE, "libsurvive", device="HMD")
    board = load_board(FIXTURE.parent / "hmd_board.toml")  # the fixture has no CONFIG line
    assert len(board.ids) == 32
    models = models_of(decoded.calibrations)
    result = solve_graph(board, decoded.angles, models)
    ls = read_libsurvive_poses(Path(str(FIXTURE) + ".json"))
    ours, theirs = result.stations.pose(1), inverse(ls[1]) @ ls[0]
    # frame-independent: station distance and relative rotation angle. libsurvive is no
    # ground truth: its solution uses its own gib sign, which alone moves the relative
    # rotation by ~2 deg here (docs/results/libsurvive_check.md)
    assert abs(np.linalg.norm(ours[:3, 3]) - np.linalg.norm(theirs[:3, 3])) < 0.15
    assert abs(np.degrees(rotation_angle(ours[:3, :3]) - rotation_angle(theirs[:3, :3]))) < 3.0
    assert np.median(np.abs(result.residuals.residual_rad)) < 1e-4
    assert result.residuals.inlier_fraction() > 0.7


def test_board_from_the_full_recording(shared_data):
    path = shared_data / "libsurvive-lh1" / "lh1_test_cal.rec.gz"
    board = read_libsurvive_board(path, "HMD")
    committed = load_board(FIXTURE.parent / "hmd_board.toml")
    np.testing.assert_allclose(board.positions, committed.positions)
    assert 0.08 < np.ptp(board.positions[:, 0]) < 0.25  # an HMD is ~18 cm wide
