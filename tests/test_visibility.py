"""The co-visibility graph (issue #41 item 3, :mod:`lhgraph.estimation.visibility`): links
counted from sweeps seen together, hops from the reference, captures per station; its
figure and the coverage figure of a 16-station room; a simulated 16-station room cut into
captures that each see 2-4 stations, solved jointly within 2 mm / 0.05 deg of the truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.metrics import station_errors
from lhgraph.estimation.visibility import co_visibility
from lhgraph.io.angles import Angles
from lhgraph.io.captures import join_captures
from lhgraph.report.figures import png_bytes
from lhgraph.report.html import coverage_figure
from lhgraph.report.visibility import plan_coordinates, visibility_figure, visibility_rows
from lhgraph.sim.room_captures import room_captures
from lhgraph.sim.simulate import load_simulation_config, simulate

ROOM16 = Path(__file__).resolve().parent.parent / "configs" / "simulation" / "lh2_room16.toml"


def sweeps(station: int, t: np.ndarray, capture: int = 0) -> Angles:
    """One hit per sweep of ``station`` at times ``t`` (sweep numbers unique per station and
    capture)."""
    n = len(t)
    return Angles(t, np.full(n, station), np.zeros(n, dtype=np.int64),
                  np.zeros(n, dtype=np.int64), np.zeros(n),
                  {"capture": np.full(n, capture),
                   "sweep": np.arange(n) + 1000 * station + 100000 * capture})


def joined(*parts: Angles) -> Angles:
    cols = ("time", "lighthouse", "axis", "sensor", "angle")
    a = {c: np.concatenate([getattr(p, c) for p in parts]) for c in cols}
    extra = {k: np.concatenate([p.extra[k] for p in parts]) for k in parts[0].extra}
    order = np.argsort(a["time"], kind="stable")
    return Angles(*(a[c][order] for c in cols), {k: v[order] for k, v in extra.items()})


def test_links_hops_and_captures():
    t = np.arange(0, 1, 0.02)
    angles = joined(sweeps(0, t), sweeps(1, t + 0.01), sweeps(1, 5 + t, 1),
                    sweeps(2, 5 + t + 0.04, 1), sweeps(3, 10 + t, 2))
    vis = co_visibility(angles)
    assert set(vis.links) == {(0, 1), (1, 2)}
    assert vis.links[(0, 1)] == 2 * len(t)  # every sweep of either within 50 ms of the other
    assert vis.hops(0) == {0: 0, 1: 1, 2: 2}  # station 3 never seen with another
    assert vis.captures == {0: [0], 1: [0, 1], 2: [1], 3: [2]}
    rows = visibility_rows(vis, 0)
    assert rows[3] == ["3", str(len(t)), "2", "none", "not linked"]
    positions = {k: np.array([k, k % 2, 2.5]) for k in range(4)}
    assert png_bytes(visibility_figure(vis, positions, 0), 60)[:4] == b"\x89PNG"


def test_plan_is_the_stations_plane():
    ring = np.c_[3 * np.cos(np.linspace(0, 6, 16)), 2 * np.sin(np.linspace(0, 6, 16)),
                 np.full(16, 2.5)]
    R = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    plan = plan_coordinates(ring @ R.T + 1.0)  # any world frame
    d = np.linalg.norm(plan[:, None] - plan[None], axis=2)
    assert np.allclose(d, np.linalg.norm(ring[:, None] - ring[None], axis=2))


@pytest.fixture(scope="module")
def room16():
    config = dataclasses.replace(load_simulation_config(ROOM16), duration_s=16.0)
    config = dataclasses.replace(config, motion=dataclasses.replace(config.motion,
                                                                    speed_mps=1.6))
    return simulate(config, 4)


def test_a_16_station_room_in_captures_of_2_to_4(room16):
    captures = room_captures(room16.angles, 2.0)
    seen = [c.stations() for c in captures]
    assert all(2 <= len(s) <= 4 for s in seen) and len(captures) >= 6
    assert all(set(a) & set(b) for a, b in zip(seen, seen[1:], strict=False))
    angles, _, _ = join_captures(captures, [f"part {i}" for i in range(len(captures))])
    vis = co_visibility(angles)
    assert max(len(vis.neighbours(k)) for k in vis.stations()) < 8
    models = {k: s.model for k, s in room16.truth.stations.items()}
    result = solve_graph(room16.board, angles, models)
    assert result.status == "converged" and result.stations.reference == 0
    hops = vis.hops(0)
    assert set(hops) == set(result.stations.indices()) and max(hops.values()) >= 3
    for e in station_errors(room16.truth, result.stations):
        assert e.position_norm_m < 2e-3 and np.degrees(e.rotation_rad) < 0.05, e
    fig = coverage_figure(angles)
    assert len(fig.axes) >= 2 * len(vis.stations())  # a panel and its colour bar each
