"""The whole chain on real components: simulated signal -> .lhcap -> decode -> graph solve."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.signal.capture import read_capture
from lhgraph.signal.decode import decode_capture
from lhgraph.sim.capture_sim import write_simulated_capture
from lhgraph.sim.simulate import load_simulation_config, simulate
from lhgraph.workflow.inputs import models_of

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "simulation" / "realistic.toml"


def test_capture_decode_solve(tmp_path):
    # realistic: a real LH1 pair's factory calibration, 65 urad noise, reflections, dropouts;
    # station 0 flashes first so decoded indices equal the simulator's (docs/decoding.md)
    cfg = load_simulation_config(CONFIG)
    sim = simulate(dataclasses.replace(cfg, duration_s=8.0, first_station=0), 3)
    path = write_simulated_capture(sim, tmp_path)
    capture, warnings = read_capture(path)
    assert not warnings
    decoded = decode_capture(capture)
    assert set(decoded.calibrations) == {0, 1}  # OOTX frames came through the sync widths
    models = models_of(decoded.calibrations)
    result = solve_graph(sim.board, decoded.angles, models)
    truth = sim.truth.relative_to_reference()
    err = np.linalg.norm(result.stations.pose(1)[:3, 3] - truth.pose(1)[:3, 3])
    assert err < 3e-3
