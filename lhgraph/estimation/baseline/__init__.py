"""The paper's calibration pipeline (Jansen et al.), ``method = "paper"``: our baseline.

Steps (paper §"Proposed Automatic Calibration Algorithm"):

1. per station, reconstruct measurements with both angles (:mod:`lhgraph.estimation.reconstruct`),
   after removing the factory-calibration distortion when a model is given;
2. per measurement, the board pose with the station at the origin: Nelder-Mead on
   ``K1 = ||C(L, P) - M||_F^2`` (:func:`estimate_board_pose`, :func:`estimate_board_poses`);
   poses whose K1 residual is an outlier among the station's are dropped
   (:func:`reject_outlier_poses`, ours, not the paper's);
3. the reference ("master") station's board path; every other ("slave") station's path
   interpolated to the master's timestamps (:func:`interpolate_path`);
4. weighted Kabsch superposition of the two paths -> initial ``T_ref_slave``
   (:func:`initial_station_pose`);
5. Nelder-Mead on ``K2 = sum_n ||C(L, P_n) - M_n||_F^2`` over the slave's measurements with
   the master path fixed (:func:`refine_station_pose`), without the measurements dropped
   in step 2.

:func:`solve_paper` runs it all (:mod:`~lhgraph.estimation.baseline.pipeline`); the steps live
in :mod:`~lhgraph.estimation.baseline.board_poses` (2) and
:mod:`~lhgraph.estimation.baseline.station_pose` (3-5), the K1/K2 angle cost in
:mod:`~lhgraph.estimation.baseline.cost`, the settings in
:mod:`~lhgraph.estimation.baseline.options`. Frames: ``T_lh_board`` maps board points (m) into a
station frame (+x forward, +y left, +z up); the world is the reference station's frame.
Angles in rad, times in s. See docs/baseline.md for every choice the paper leaves open.
"""

from lhgraph.estimation.baseline.options import PaperOptions
from lhgraph.estimation.baseline.pipeline import solve_paper

__all__ = ["PaperOptions", "solve_paper"]
