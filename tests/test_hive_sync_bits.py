"""The per-sweep sync-bit offsets of hive's angles: found and corrected
(:mod:`lhgraph.importers.hive.sync_offsets`), on synthetic series and on the real bag."""

from __future__ import annotations

import numpy as np
import pytest

from lhgraph.importers.hive.sync_offsets import DATA_BIT_RAD, correct_sync_bits
from lhgraph.io.angles import Angles
from lhgraph.workflow.window import motion_start


def _series(low_runs: bool, seed: int = 0, n_sweeps: int = 600) -> tuple[Angles, np.ndarray]:
    """Two stations x two axes of 30 Hz sweeps of 5 diodes on a moving board (angles
    swinging +-0.3 rad at up to ~1 rad/s), 50 µrad noise; with ``low_runs`` station 1's
    sweeps read one data bit low in runs of 1-6 sweeps (~40 %). Returns the angles and
    the truth: per row whether it was lowered."""
    rng = np.random.default_rng(seed)
    rows = []
    low_rows = []
    for lh in (0, 1):
        for ax in (0, 1):
            t0 = rng.uniform(0, 0.03)
            level = False
            for k in range(n_sweeps):
                t = t0 + k / 30.0 + rng.normal(0, 2e-4)
                if lh == 1 and low_runs and rng.random() < 0.3:
                    level = not level
                lowered = lh == 1 and low_runs and level
                for s in rng.choice(8, 5, replace=False):
                    truth = 0.3 * np.sin(1.3 * t + lh + 2 * ax) + 0.01 * s
                    angle = truth + rng.normal(0, 5e-5) - DATA_BIT_RAD * lowered
                    rows.append((t, lh, ax, s, angle))
                    low_rows.append(lowered)
    order = np.argsort([r[0] for r in rows], kind="stable")
    cols = [np.array([rows[i][j] for i in order]) for j in range(5)]
    a = Angles(cols[0], cols[1].astype(np.int64), cols[2].astype(np.int64),
               cols[3].astype(np.int64), cols[4])
    return a, np.array(low_rows)[order]


def test_low_runs_found_and_raised():
    angles, lowered = _series(low_runs=True)
    fixed, found = correct_sync_bits(angles)
    assert not found.corrected[(0, 0)] and not found.corrected[(0, 1)]
    for ax in (0, 1):
        lev = found.levels[(1, ax)]
        assert found.corrected[(1, ax)]
        assert 0.3 < lev.fraction_low < 0.7
        assert abs(lev.gap_rad - DATA_BIT_RAD) < 2e-5
    # the lowered hits raised by the fitted gap, the others not moved (a sweep whose
    # neighbours share too few of its diodes can go either way: at most 1 in 200)
    raised = fixed.angle - angles.angle
    assert np.mean((raised > 0) != lowered) < 0.005
    assert np.allclose(raised[raised > 0], DATA_BIT_RAD, atol=2e-5)
    assert "read 7.8" in found.summary() and "lh0/ax0: no sync-bit offset" in found.summary()


def test_levels_of_another_size_left_alone():
    # runs of sweeps 3 mrad low are no sync-bit offset (the data bit is 7.86 mrad)
    angles, lowered = _series(low_runs=True, seed=2)
    odd = angles.select(np.arange(len(angles)))
    odd.angle = np.where(lowered, angles.angle + DATA_BIT_RAD - 3e-3, angles.angle)
    fixed, found = correct_sync_bits(odd)
    assert not any(found.corrected.values())
    assert np.array_equal(fixed.angle, odd.angle)
    assert "left as they are" in found.summary()


def test_clean_series_left_alone():
    angles, _ = _series(low_runs=False, seed=1)
    fixed, found = correct_sync_bits(angles)
    assert not any(found.corrected.values())
    assert np.array_equal(fixed.angle, angles.angle)


def test_bag_station_1_levels_match_the_rest_period(hive_bag, tmp_path):
    from lhgraph.importers.hive import import_hive
    from lhgraph.io.angles import load_angles

    result = import_hive(hive_bag, tmp_path, sync_bits=False)
    assert result.sync_bits is None
    raw = load_angles(tmp_path / "angles.csv")
    fixed, found = correct_sync_bits(raw)
    assert not found.corrected[(0, 0)] and not found.corrected[(0, 1)]
    rest_end = motion_start(raw) - 0.5
    ids = raw.sweep_ids()
    for ax in (0, 1):
        assert found.corrected[(1, ax)]
        lev = found.levels[(1, ax)]
        assert 0.35 < lev.fraction_low < 0.45
        assert abs(lev.gap_rad - DATA_BIT_RAD) < 5e-5
        # while the tracker rests each sensor's angle is constant: a sweep is low when its
        # diodes read half a gap below their medians at rest (benchmarks/hive_sync_offsets.py)
        sel = np.flatnonzero((raw.lighthouse == 1) & (raw.axis == ax))
        rest = sel[raw.time[sel] < rest_end]
        median = {s: np.median(raw.angle[rest][raw.sensor[rest] == s])
                  for s in np.unique(raw.sensor[rest])}
        dev = raw.angle[rest] - np.array([median[s] for s in raw.sensor[rest]])
        sweeps, inv = np.unique(ids[rest], return_inverse=True)
        low_at_rest = np.bincount(inv, weights=dev) / np.bincount(inv) < -DATA_BIT_RAD / 2
        raised = np.bincount(inv, weights=fixed.angle[rest] - raw.angle[rest]) > 0
        assert low_at_rest.sum() > 30
        assert np.array_equal(raised, low_at_rest)


@pytest.mark.parametrize("flag, corrected", [([], True), (["--keep-sync-offsets"], False)])
def test_cli_reports_the_correction(hive_bag, tmp_path, capsys, flag, corrected):
    from lhgraph.cli import main

    assert main(["import", "hive", str(hive_bag), "--output", str(tmp_path), *flag]) == 0
    out = capsys.readouterr().out
    assert ("lh1/ax0: " in out and "raised" in out) == corrected
    assert ("not looked for" in out) != corrected
