"""lhgraph view: the scene of a run directory and its headless export."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.io.stations import save_stations
from lhgraph.io.trajectory import save_trajectory
from lhgraph.model.board import save_board
from lhgraph.report.viewer import build_scene, export, frustum_segments
from lhgraph.sim.simulate import default_simulation_config, simulate
from lhgraph.workflow.rundir import run_to_directory
from lhgraph.workflow.solve_config import SolveConfig


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run directory made from a simulation's truth (no solve needed for the viewer)."""
    out = tmp_path_factory.mktemp("run")
    sim = simulate(dataclasses.replace(default_simulation_config(), duration_s=0.5), seed=2)
    save_stations(sim.truth, out / "stations.toml")
    save_trajectory(sim.trajectory, out / "trajectory.csv")
    save_board(sim.board, out / "board.toml")
    return out


def test_frustum_geometry() -> None:
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 3.0]
    seg = frustum_segments(T, depth_m=2.0, half_angle_deg=45.0)
    assert seg.shape == (8, 2, 3)
    far = seg[:4, 1] - T[:3, 3]
    np.testing.assert_allclose(far[:, 0], 2.0)
    np.testing.assert_allclose(np.abs(far[:, 1:]), 2.0)


def test_scene_contents(run_dir: Path) -> None:
    from lhgraph.model.board import load_board

    board = load_board(run_dir / "board.toml")
    scene = build_scene(run_dir, board, board_poses=3)
    n_stations = 2
    n_path = len((run_dir / "trajectory.csv").read_text().splitlines()) - 2
    assert len(scene.segments) == n_stations * (3 + 8) + n_path
    assert len(scene.points) == 3 * len(board.ids)
    # the reference station's x axis starts at the origin and points along +x
    np.testing.assert_allclose(scene.segments[0], [[0, 0, 0], [0.3, 0, 0]], atol=1e-12)


def test_export_png_matplotlib_and_refusals(run_dir: Path, tmp_path: Path) -> None:
    scene = build_scene(run_dir)
    path, how = export(scene, tmp_path / "v.png", renderer="matplotlib")
    assert how == "matplotlib" and path.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(InputError, match="exists already"):
        export(scene, tmp_path / "v.png")
    with pytest.raises(InputError, match="unknown export format"):
        export(scene, tmp_path / "v.jpg")
    with pytest.raises(InputError, match="not a run directory"):
        build_scene(tmp_path)


def test_export_ply_with_open3d(run_dir: Path, tmp_path: Path) -> None:
    o3d = pytest.importorskip("open3d", reason="open3d not importable (e.g. libusb missing)",
                              exc_type=ImportError)
    assert main(["view", str(run_dir), "--export", str(tmp_path / "v.ply"), "--quiet"]) == 0
    mesh = o3d.io.read_triangle_mesh(str(tmp_path / "v.ply"))
    assert len(mesh.triangles) > 0 and mesh.has_vertex_colors()
    lo, hi = mesh.get_min_bound(), mesh.get_max_bound()
    assert np.all(lo < 0.05) and np.all(hi > -0.05)  # the reference station at the origin


def test_run_directory_board_found_from_summary(tmp_path: Path) -> None:
    """A run directory written by `lhgraph solve` names its board in summary.json."""
    sim = simulate(dataclasses.replace(default_simulation_config(), duration_s=1.0), seed=4)
    from lhgraph.sim.simulate import write_simulation

    write_simulation(sim, tmp_path / "in")
    config = SolveConfig(tmp_path / "in/board.toml", tmp_path / "in/angles.csv")
    run_to_directory(config, tmp_path / "run")
    scene = build_scene(tmp_path / "run", board_poses=2)
    assert len(scene.points) == 2 * len(sim.board.ids)


@pytest.fixture(scope="module")
def two_method_dir(run_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A multi-method run directory's layout: one run directory per method."""
    import shutil

    out = tmp_path_factory.mktemp("two")
    for method in ("graph", "paper"):
        shutil.copytree(run_dir, out / method)
    return out


def test_multi_method_run_directory(two_method_dir: Path, run_dir: Path, tmp_path: Path,
                                    capsys: pytest.CaptureFixture) -> None:
    one = build_scene(run_dir)
    both = build_scene(two_method_dir)
    assert len(both.segments) == 2 * len(one.segments)
    assert len(build_scene(two_method_dir, method="paper").segments) == len(one.segments)
    with pytest.raises(InputError, match="no method 'lm' here \\(methods: graph, paper\\)"):
        build_scene(two_method_dir, method="lm")
    png = tmp_path / "both.png"
    assert main(["view", str(two_method_dir), "--export", str(png),
                 "--renderer", "matplotlib"]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG" and "matplotlib" in capsys.readouterr().out


@pytest.mark.parametrize("env", [{}, {"DISPLAY": ":987"}])
def test_view_without_display_says_what_it_needs(run_dir: Path, env: dict[str, str],
                                                 monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture) -> None:
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    monkeypatch.setattr("sys.platform", "linux")
    assert main(["view", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "display" in err and "--export FILE.png" in err


class _NoLibusb:
    """An import hook that fails ``import open3d`` as a machine without libusb does."""

    def find_spec(self, name, path=None, target=None):
        if name == "open3d":
            raise OSError("libusb-1.0.so.0: cannot open shared object file: No such file")
        return None


@pytest.mark.parametrize("broken", ["missing", "no-libusb"])
def test_export_without_open3d_falls_back_to_matplotlib_and_says_so(
        run_dir: Path, tmp_path: Path, broken: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    import sys

    monkeypatch.delitem(sys.modules, "open3d", raising=False)
    if broken == "missing":
        monkeypatch.setitem(sys.modules, "open3d", None)
    else:
        monkeypatch.setattr(sys, "meta_path", [_NoLibusb(), *sys.meta_path])
    png = tmp_path / "v.png"
    assert main(["view", str(run_dir), "--export", str(png)]) == 0
    out = capsys.readouterr().out
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert "matplotlib: Open3D cannot load here" in out, out
    if broken == "no-libusb":
        assert "libusb-1.0.so.0" in out
    # what only Open3D can do: one line, exit 2, no traceback
    assert main(["view", str(run_dir), "--export", str(tmp_path / "v.ply")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "export a .png" in err, err
    assert main(["view", str(run_dir), "--export", str(tmp_path / "w.png"),
                 "--renderer", "open3d"]) == 2
    assert "--renderer matplotlib" in capsys.readouterr().err
