"""Motion window: a simulated capture with known still and moving spans."""

from __future__ import annotations

import numpy as np
import pytest

from lhgraph.errors import InputError
from lhgraph.estimation.rests import rest_spans, thin_rests
from lhgraph.geometry.transforms import make_pose, so3_exp, transform_points
from lhgraph.io.angles import Angles
from lhgraph.model.station import ideal_angles
from lhgraph.workflow.window import motion_rate, motion_start, moving_window

SENSORS = np.array([[0.0, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.05], [0.0, -0.05, 0.02]])


def capture(move_from_s: float, move_to_s: float, total_s: float = 12.0, noise_rad: float = 65e-6,
            bump_at_s: float | None = None, seed: int = 0) -> Angles:
    """Two stations' sweeps (30 Hz per axis) of four sensors 2 m away; the board circles
    (10 cm radius, 0.5 Hz) while turning (0.3 rad/s) only within ``[move_from_s, move_to_s)``;
    also for 0.5 s from ``bump_at_s`` if given; Gaussian angle noise, 1 % gross outliers."""
    rng = np.random.default_rng(seed)
    t_sweep = np.arange(0.0, total_s, 1 / 120)
    slot = np.arange(len(t_sweep)) % 4
    lighthouse, axis = slot % 2, slot // 2
    moving = (t_sweep >= move_from_s) & (t_sweep < move_to_s)
    if bump_at_s is not None:
        moving |= (t_sweep >= bump_at_s) & (t_sweep < bump_at_s + 0.5)
    tau = np.cumsum(moving) / 120  # moving time so far, s
    y, z = 0.1 * np.sin(np.pi * tau), 0.3 + 0.1 * (1 - np.cos(np.pi * tau))
    T_lh_board = make_pose(so3_exp(np.outer(0.3 * tau, [0.0, 0.0, 1.0])), np.c_[2.0 + 0 * y, y, z])
    # station 1 looks at the board from the side: rotate the points by 90 deg about z
    p = transform_points(T_lh_board[:, None], SENSORS[None])
    side = np.where(lighthouse[:, None, None] == 1, p[..., [1, 0, 2]] * [1, -1, 1] + [2, 0, 0], p)
    ang = ideal_angles(side)[np.arange(len(t_sweep)), :, axis]
    ang = ang + rng.normal(0.0, noise_rad, ang.shape)
    outlier = rng.random(ang.shape) < 0.01
    ang[outlier] += rng.normal(0.0, 0.05, outlier.sum())
    n = len(SENSORS)
    return Angles(np.repeat(t_sweep, n) + np.tile(np.arange(n) * 2e-5, len(t_sweep)),
                  np.repeat(lighthouse, n), np.repeat(axis, n), np.tile(np.arange(n), len(t_sweep)),
                  ang.ravel())


def test_start_of_motion_is_found_within_a_bin():
    a = capture(3.0, 9.0)
    assert motion_start(a) == pytest.approx(3.0, abs=0.25)


def test_window_has_the_requested_span_from_the_start_of_motion():
    a = capture(2.5, 11.0)
    w = moving_window(a, 4.0)
    assert w.time.min() == pytest.approx(2.5, abs=0.25)
    assert w.time.max() - w.time.min() == pytest.approx(4.0, abs=0.02)
    assert np.all(np.isin(w.time, a.time))
    assert len(w) < len(a)


def test_window_is_cut_short_by_the_end_of_the_capture():
    a = capture(10.0, 12.0, total_s=12.0)
    w = moving_window(a, 8.0)
    assert w.time.min() == pytest.approx(10.0, abs=0.25)
    assert w.time.max() == pytest.approx(a.time.max())


def test_a_short_bump_is_not_the_start():
    a = capture(6.0, 12.0, bump_at_s=2.0)
    rate_t, rate = motion_rate(a)
    bump = (rate_t >= 2.0) & (rate_t < 2.5)
    assert np.nanmax(rate[bump]) > 0.01  # the bump is seen ...
    assert motion_start(a) == pytest.approx(6.0, abs=0.25)  # ... but is not the start


def test_still_capture_is_refused_with_one_line():
    a = capture(5.0, 5.0)
    with pytest.raises(InputError, match="never moves"):
        moving_window(a, 8.0)


def test_rest_rate_is_noise_and_moving_rate_is_far_above_threshold():
    a = capture(4.0, 8.0)
    t, rate = motion_rate(a)
    still, moving = (t < 3.5) | (t > 8.5), (t > 4.5) & (t < 7.5)
    assert np.nanmax(rate[still]) < 0.005
    assert np.nanmin(rate[moving]) > 0.02


def test_non_positive_duration_is_refused():
    with pytest.raises(InputError, match="duration"):
        moving_window(capture(1.0, 5.0), 0.0)


def test_rests_are_found_and_thinned_to_whole_windows():
    """Rests before 3 s and after 9 s (a 0.5 s bump at 10 s: two rests there, the shorter
    one, 9-10 s, still one); thinning keeps every moving hit, about one 0.1 s window in
    ``keep_every`` of each rest, in whole windows (every station and axis alike)."""
    a = capture(3.0, 9.0, total_s=14.0, bump_at_s=10.0)
    spans = rest_spans(a)
    assert len(spans) == 3
    np.testing.assert_allclose(spans[:, 0], [0.0, 9.0, 10.5], atol=0.26)
    np.testing.assert_allclose(spans[:, 1], [3.0, 10.0, 14.0], atol=0.26)
    thinned, report = thin_rests(a, 10)
    in_rest = np.zeros(len(a), dtype=bool)
    for t0, t1 in spans:
        in_rest |= (a.time >= t0) & (a.time < t1)
    assert np.all(np.isin(a.time[~in_rest], thinned.time))  # the motion is all kept
    kept = np.isin(a.time, thinned.time) & in_rest
    assert report.hits_kept == kept.sum() and report.hits_dropped == len(a) - len(thinned)
    assert kept.sum() / in_rest.sum() == pytest.approx(0.1, abs=0.03)
    window = np.floor(a.time[kept] * 1e4).astype(int) // 1000  # 0.1 s windows of kept hits
    cycles = np.bincount(a.lighthouse[kept] * 2 + a.axis[kept], minlength=4)
    assert cycles.min() >= 0.9 * cycles.max() and len(np.unique(window)) >= 5
    assert "3 rest(s)" in report.summary()
    same, none = thin_rests(a, 1)
    assert same is a and none.hits_dropped == 0
