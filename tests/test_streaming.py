"""Streaming (incremental fixed-lag iSAM2) calibration on a simulated capture."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.errors import SolverError
from lhgraph.estimation.graph.streaming import StreamingSolver, cycles
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "simulation" / "default.toml"


def test_streaming_converges_and_reports_live():
    sim = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=4.0), 2)
    solver = StreamingSolver(sim.board, [0, 1], warmup_s=1.0)
    with pytest.raises(SolverError, match="warming up"):
        solver.estimate()
    T_true = sim.truth.relative_to_reference().pose(1)
    chunks = list(cycles(sim.angles))
    assert 100 < len(chunks) < 140  # 4 s of 33 ms sync cycles
    errors, times = [], []
    for chunk in chunks:
        est = solver.add(chunk)
        if est is not None:
            errors.append(np.linalg.norm(se3_log(inverse(T_true) @ est.stations[1])[3:]))
            times.append(est.time)
    assert len(errors) > 60
    assert np.all(np.diff(times) > 0)
    assert errors[-1] < 2e-3
    cov = solver.estimate().covariances[1]
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_cycles_cover_every_hit_once():
    sim = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=1.0), 3)
    parts = list(cycles(sim.angles))
    assert sum(len(p) for p in parts) == len(sim.angles)
    np.testing.assert_array_equal(np.concatenate([p.time for p in parts]), sim.angles.time)
