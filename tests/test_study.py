"""Studies: Table III statistics (known answers), config validation, a resumable small study
run in parallel processes, and the same on a local Dask cluster."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import make_pose, so3_exp
from lhgraph.io.stations import Station, Stations
from lhgraph.workflow.study import (
    load_study_config,
    protocol_statistics,
    result_file,
    run_study,
    signed_errors,
    table_iii_markdown,
)

REPO = Path(__file__).resolve().parents[1]


def test_protocol_statistics_known_answer() -> None:
    a = np.array([1.0, -2, 3, 0.1, -0.2, 0.3])
    names = ["s1/m1", "s1/m2", "s2/m1", "s2/m2"]
    signed = [a, 3 * a, -a, -a]
    stats = protocol_statistics(names, signed)
    np.testing.assert_allclose(stats.mae, 1.5 * np.abs(a))
    # setup 1: std(ddof=1) of (a, 3a) = sqrt(2) |a|; setup 2: 0 -> mean sqrt(2)/2 |a|
    np.testing.assert_allclose(stats.sd, np.sqrt(2) / 2 * np.abs(a))
    assert stats.captures == 4
    lines = table_iii_markdown({"x": stats})
    assert lines[2].startswith("| x MAE | 1.500 | 3.000 | 4.500 | 0.1500 |")


def test_signed_errors_in_reference_frame() -> None:
    T1 = make_pose(so3_exp([0, 0, 0.3]), [2.0, 0.5, 0.1])
    truth = Stations(0, {0: Station(np.eye(4)), 1: Station(T1)})
    dT = make_pose(so3_exp([0, 0, np.radians(0.1)]), [0.001, -0.002, 0.0])
    # an estimate in another world frame: both stations moved by the same rigid transform
    W = make_pose(so3_exp([0.2, -0.1, 1.0]), [5.0, 1.0, -2.0])
    est = Stations(0, {0: Station(W), 1: Station(W @ T1 @ dT)})
    e = signed_errors(truth, est)
    assert e.shape == (1, 6)
    np.testing.assert_allclose(e[0, :3], T1[:3, :3] @ [1.0, -2.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(e[0, 3:], [0, 0, 0.1], atol=1e-9)  # [roll, pitch, yaw]


@pytest.mark.parametrize(("text", "key"), [
    ('protocol = "nope.toml"\n', "protocol"),
    ('methods = ["graph"]\n', "protocol"),
    ('protocol = "p.toml"\nmethods = ["fast"]\n', "methods"),
    ('protocol = "p.toml"\nsetups = 0\n', "setups"),
    ('protocol = "p.toml"\nduration_s = "3"\n', "duration_s"),
    ('protocol = "p.toml"\n[paper]\nwarm_start = 1\n', "paper.warm_start"),
    ('protocol = "p.toml"\n[paper]\nfoo = 1\n', "paper.foo"),
    ('protocol = "p.toml"\njobs = 2\n', "jobs"),
])
def test_study_config_errors(tmp_path: Path, text: str, key: str) -> None:
    (tmp_path / "p.toml").write_text((REPO / "configs/paper_simulation.toml").read_text())
    path = tmp_path / "study.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_study_config(path)
    assert str(path) in str(info.value) and key in str(info.value)


def test_small_study_runs_and_resumes(tmp_path: Path) -> None:
    """configs/study_small.toml: 4 captures x 2 methods on 2 processes, then a rerun reuses
    every stored result; a changed option reruns only that method."""
    study = load_study_config(REPO / "configs/study_small.toml")
    assert [n for n, _ in study.cases()] == ["setup01/meas1", "setup01/meas2",
                                            "setup02/meas1", "setup02/meas2"]
    assert all(c.duration_s == 3.0 for _, c in study.cases())
    out = tmp_path / "study"
    result = run_study(study, out, jobs=2)
    assert result.ran == 8 and result.skipped == 0
    stats = result.statistics()
    assert set(stats) == {"graph", "paper"}
    assert stats["graph"].captures == 4
    # the factor graph beats the paper's pipeline on every axis's MAE here
    assert np.all(stats["graph"].mae < stats["paper"].mae)
    for name in ("study.md", "study.json", "error_vs_speed.png", "error_vs_distance.png"):
        assert (out / name).is_file()
    text = (out / "study.md").read_text()
    assert "method graph MAE" in text and "paper MAE (Table III) | 6.9" in text
    graph_mm = [max(json.loads(result_file(out, n, "graph").read_text())["position_mm"])
                for n, _ in study.cases()]
    paper_mm = [max(json.loads(result_file(out, n, "paper").read_text())["position_mm"])
                for n, _ in study.cases()]
    smaller = sum(g < p for g, p in zip(graph_mm, paper_mm, strict=True))
    assert f"| graph | paper | 4 | {smaller} | " in text
    again = run_study(study, out, jobs=2)
    assert again.ran == 0 and again.skipped == 8
    np.testing.assert_allclose(again.statistics()["graph"].mae, stats["graph"].mae)
    record = json.loads(result_file(out, "setup01/meas1", "graph").read_text())
    assert record["speed_mps"] > 0 and record["distance_m"] > 0


def test_refuses_foreign_directory(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not a study directory"):
        run_study(load_study_config(REPO / "configs/study_small.toml"), tmp_path)


def test_dask_local_cluster(tmp_path: Path) -> None:
    """The same study code on a Dask scheduler (a loopback LocalCluster, one worker)."""
    distributed = pytest.importorskip("distributed", reason="dask[distributed] not installed")
    (tmp_path / "p.toml").write_text((REPO / "configs/paper_simulation.toml").read_text())
    path = tmp_path / "tiny.toml"
    path.write_text('protocol = "p.toml"\nmethods = ["graph"]\nsetups = 1\nmeasurements = 1\n'
                    'duration_s = 1.5\n')
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1",
                                  dashboard_address=None, processes=True) as cluster:
        result = run_study(load_study_config(path), tmp_path / "out",
                           scheduler=cluster.scheduler_address)
    assert result.ran == 1 and "error" not in result.records[0]
    assert max(result.records[0]["position_mm"]) < 50.0
