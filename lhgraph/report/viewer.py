"""3-D view of a run directory: stations with their sweep frusta, board path, diodes.

:func:`build_scene` turns a run directory (``stations.toml``, ``trajectory.csv``; the board
from the run's ``summary.json`` inputs) into plain numpy primitives in the world frame
(reference station, m); a multi-method run directory gives every method's stations and
paths. :func:`show` opens them in an Open3D window; :func:`export` writes
a mesh (``.ply``, ``.glb``, ``.obj`` via Open3D, headless) or a PNG (Open3D's offscreen
renderer when it works, else matplotlib). Open3D is imported only inside these functions
(importing it takes seconds).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import transform_points
from lhgraph.io.files import check_writable, read_json_object, write_atomic
from lhgraph.io.stations import load_stations
from lhgraph.io.trajectory import load_trajectory
from lhgraph.model.board import Board, load_board
from lhgraph.report.figures import png_bytes

FRUSTUM_DEPTH_M = 1.0
FRUSTUM_HALF_ANGLE_DEG = 60.0  # the stations' sweep field of view per axis
AXIS_LENGTH_M = 0.3
BOARD_POSES = 5
MESH_FORMATS = (".ply", ".glb", ".gltf", ".obj")


@dataclass
class Scene:
    """Line segments (N, 2, 3) with RGB colours (N, 3) and points (M, 3) with colours,
    world frame (m)."""

    segments: NDArray[np.float64] = field(default_factory=lambda: np.empty((0, 2, 3)))
    segment_colours: NDArray[np.float64] = field(default_factory=lambda: np.empty((0, 3)))
    points: NDArray[np.float64] = field(default_factory=lambda: np.empty((0, 3)))
    point_colours: NDArray[np.float64] = field(default_factory=lambda: np.empty((0, 3)))

    def add_segments(self, seg: NDArray, colour: tuple[float, float, float]) -> None:
        """Append segments of one colour."""
        seg = np.asarray(seg, dtype=float).reshape(-1, 2, 3)
        self.segments = np.concatenate([self.segments, seg])
        self.segment_colours = np.concatenate([self.segment_colours,
                                               np.tile(colour, (len(seg), 1))])

    def add_points(self, pts: NDArray, colour: tuple[float, float, float]) -> None:
        """Append points of one colour."""
        pts = np.asarray(pts, dtype=float).reshape(-1, 3)
        self.points = np.concatenate([self.points, pts])
        self.point_colours = np.concatenate([self.point_colours, np.tile(colour, (len(pts), 1))])


def frustum_segments(T_world_lh: NDArray, depth_m: float = FRUSTUM_DEPTH_M,
                     half_angle_deg: float = FRUSTUM_HALF_ANGLE_DEG) -> NDArray[np.float64]:
    """The 8 edges (8, 2, 3) of a station's sweep frustum: apex at the station, far
    rectangle at ``depth_m`` along +x spanning +-``half_angle_deg`` in azimuth and elevation."""
    t = depth_m * np.tan(np.radians(half_angle_deg))
    corners = np.array([[depth_m, s * t, u * t] for s, u in ((1, 1), (-1, 1), (-1, -1), (1, -1))])
    c = transform_points(T_world_lh, corners)
    o = T_world_lh[:3, 3]
    return np.array([[o, c[i]] for i in range(4)] + [[c[i], c[(i + 1) % 4]] for i in range(4)])


def _run_board(run_dir: Path) -> Board | None:
    summary = read_json_object(run_dir / "summary.json") or {}
    inputs = summary.get("inputs")
    board = inputs.get("board") if isinstance(inputs, dict) else None
    path = board.get("path") if isinstance(board, dict) else None
    return load_board(path) if isinstance(path, str) and Path(path).is_file() else None


PATH_COLOURS = ((1.0, 0.5, 0.0), (0.6, 0.2, 0.7), (0.1, 0.6, 0.6), (0.5, 0.4, 0.1))


def method_directories(run_dir: str | Path) -> list[Path]:
    """The run directories a path holds: itself when it has ``stations.toml``, else each
    method's subdirectory of a multi-method run (sorted); InputError when neither."""
    run_dir = Path(run_dir)
    if (run_dir / "stations.toml").is_file():
        return [run_dir]
    subdirs = sorted(p for p in run_dir.iterdir() if (p / "stations.toml").is_file()) \
        if run_dir.is_dir() else []
    if not subdirs:
        raise InputError("no stations.toml: not a run directory", run_dir)
    return subdirs


def build_scene(run_dir: str | Path, board: Board | None = None,
                board_poses: int = BOARD_POSES, method: str | None = None) -> Scene:
    """Scene of a run directory: station axes (x red, y green, z blue) and sweep frusta
    (grey), the board path (orange; a multi-method run: one colour per method) and the
    board's diodes at ``board_poses`` poses along it (blue). A multi-method run directory
    shows every method, or only ``method``."""
    folders = method_directories(run_dir)
    if method is not None:
        chosen = [f for f in folders if f.name == method]
        if not chosen:
            raise InputError(f"no method '{method}' here (methods: "
                             f"{', '.join(f.name for f in folders)})", run_dir, "--method")
        folders = chosen
    scene = Scene()
    for folder, path_colour in zip(folders, PATH_COLOURS * len(folders), strict=False):
        _add_run(scene, folder, board, board_poses, path_colour)
    return scene


def _add_run(scene: Scene, run_dir: Path, board: Board | None, board_poses: int,
             path_colour: tuple[float, float, float]) -> None:
    """One method's stations, frusta, board path and diodes into ``scene``."""
    stations = load_stations(run_dir / "stations.toml").relative_to_reference()
    for k in stations.indices():
        T = stations.pose(k)
        for i, colour in enumerate(((1, 0, 0), (0, 0.7, 0), (0, 0, 1))):
            scene.add_segments([T[:3, 3], T[:3, 3] + AXIS_LENGTH_M * T[:3, i]], colour)
        scene.add_segments(frustum_segments(T), (0.6, 0.6, 0.6))
    traj_file = run_dir / "trajectory.csv"
    if traj_file.is_file():
        traj = load_trajectory(traj_file)
        p = traj.T_world_board[:, :3, 3]
        scene.add_segments(np.stack([p[:-1], p[1:]], axis=1), path_colour)
        board = board or _run_board(run_dir)
        if board is not None and board_poses > 0:
            for i in np.linspace(0, len(traj.time) - 1, board_poses).round().astype(int):
                scene.add_points(transform_points(traj.T_world_board[i], board.positions),
                                 (0.1, 0.3, 0.9))


def load_open3d():
    """The ``open3d`` module, or :class:`InputError` saying why it cannot load here (it needs
    libusb and an OpenGL library at import: ``libusb-1.0.so.0``, ``libGL.so.1``)."""
    try:
        import open3d
    except (ImportError, OSError) as exc:
        raise InputError(f"Open3D cannot load here ({str(exc).splitlines()[0]})") from None
    return open3d


def to_open3d(scene: Scene, point_radius_m: float = 0.01, line_radius_m: float = 0.004):
    """A single Open3D ``TriangleMesh``: a thin cylinder per segment, a sphere per point."""
    o3d = load_open3d()

    mesh = o3d.geometry.TriangleMesh()
    for (a, b), colour in zip(scene.segments, scene.segment_colours, strict=True):
        d = b - a
        length = float(np.linalg.norm(d))
        if length < 1e-9:
            continue
        cyl = o3d.geometry.TriangleMesh.create_cylinder(line_radius_m, length, resolution=6,
                                                        split=1)
        z = d / length
        x = np.cross(z, [0, 0, 1] if abs(z[2]) < 0.9 else [1, 0, 0])
        x /= np.linalg.norm(x)
        T = np.eye(4)
        T[:3, :3] = np.c_[x, np.cross(z, x), z]
        T[:3, 3] = (a + b) / 2
        cyl.transform(T)
        cyl.paint_uniform_color(colour)
        mesh += cyl
    for p, colour in zip(scene.points, scene.point_colours, strict=True):
        s = o3d.geometry.TriangleMesh.create_sphere(point_radius_m, resolution=4)
        s.translate(p)
        s.paint_uniform_color(colour)
        mesh += s
    mesh.compute_vertex_normals()
    return mesh


def display_problem() -> str | None:
    """Why no window can open here (None when a display seems available): on Linux an X11
    or Wayland display must be named by ``DISPLAY`` or ``WAYLAND_DISPLAY``, and a local X
    display's socket must exist (else Open3D falls back to an invisible offscreen window
    and waits forever)."""
    import os
    import sys

    if not sys.platform.startswith("linux") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    display = os.environ.get("DISPLAY", "")
    if not display:
        return "no display (DISPLAY and WAYLAND_DISPLAY are unset)"
    local = re.fullmatch(r":(\d+)(\.\d+)?", display)
    if local and not Path(f"/tmp/.X11-unix/X{local[1]}").exists():
        return f"display {display} is not running (no /tmp/.X11-unix/X{local[1]})"
    return None


def show(scene: Scene) -> None:
    """Open an interactive Open3D window; InputError at once (instead of waiting for a
    window that never comes) when there is no display or Open3D cannot open a window."""
    hint = "the interactive view needs a display; without one use --export FILE.png"
    problem = display_problem()
    if problem is not None:
        raise InputError(f"{problem}: {hint}")
    o3d = load_open3d()
    vis = o3d.visualization.Visualizer()
    if not vis.create_window(window_name="lhgraph view"):
        raise InputError(f"Open3D could not open a window: {hint}")
    vis.add_geometry(to_open3d(scene))
    vis.run()
    vis.destroy_window()


def _png_open3d(scene: Scene, path: Path, size: tuple[int, int]) -> str | None:
    """Render with Open3D's offscreen renderer; None when done, else why it cannot run here
    (Open3D does not load, or no GPU/EGL)."""
    try:
        o3d = load_open3d()
    except InputError as exc:
        return str(exc)
    try:
        renderer = o3d.visualization.rendering.OffscreenRenderer(*size)
    except RuntimeError:
        return "Open3D's offscreen renderer cannot run here (no EGL/GPU)"
    material = o3d.visualization.rendering.MaterialRecord()
    material.shader = "defaultLit"
    renderer.scene.add_geometry("scene", to_open3d(scene), material)
    lo, hi = _bounds(scene)
    centre = (lo + hi) / 2
    renderer.setup_camera(60.0, centre, centre + np.array([-1.0, -1.5, 1.0]) * np.max(hi - lo),
                          [0, 0, 1])
    o3d.io.write_image(str(path), renderer.render_to_image())
    return None


def _bounds(scene: Scene) -> tuple[NDArray, NDArray]:
    pts = np.concatenate([scene.segments.reshape(-1, 3), scene.points])
    return pts.min(axis=0), pts.max(axis=0)


def png_matplotlib(scene: Scene, path: str | Path, overwrite: bool = False) -> Path:
    """Render the scene's segments and points with matplotlib (no display, no GPU) into a
    PNG file (written atomically; an existing file only replaced when ``overwrite``)."""

    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    fig = Figure(figsize=(8, 6))
    ax = fig.add_subplot(projection="3d")
    ax.add_collection3d(Line3DCollection(scene.segments, colors=scene.segment_colours, lw=1))
    if len(scene.points):
        ax.scatter(*scene.points.T, c=scene.point_colours, s=3)
    lo, hi = _bounds(scene)
    centre, half = (lo + hi) / 2, np.max(hi - lo) / 2
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    return write_atomic(path, png_bytes(fig, 100), overwrite)


def export(scene: Scene, path: str | Path, overwrite: bool = False,
           renderer: str = "auto") -> tuple[Path, str]:
    """Write the scene without a display: a mesh (``.ply``/``.glb``/``.gltf``/``.obj``) or
    a ``.png``. ``renderer`` for PNGs: ``"open3d"``, ``"matplotlib"`` or ``"auto"`` (Open3D's
    offscreen renderer, falling back to matplotlib). Returns the path and what wrote it (with
    the reason when matplotlib stood in for Open3D)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (*MESH_FORMATS, ".png"):
        raise InputError(f"unknown export format '{suffix}' (expected .png or "
                         f"{', '.join(MESH_FORMATS)})", path)
    check_writable(path, overwrite)
    if suffix == ".png":
        if renderer == "matplotlib":
            return png_matplotlib(scene, path, overwrite), "matplotlib"
        problem = _png_open3d(scene, path, (1024, 768))
        if problem is None:
            return path, "open3d"
        if renderer == "open3d":
            raise InputError(f"{problem}: --renderer matplotlib draws the PNG instead", path)
        return png_matplotlib(scene, path, overwrite), f"matplotlib: {problem}"
    try:
        o3d = load_open3d()
    except InputError as exc:
        raise InputError(f"{exc}: a {suffix} mesh needs it; export a .png (matplotlib) "
                         "instead", path) from None
    if not o3d.io.write_triangle_mesh(str(path), to_open3d(scene)):
        raise InputError("Open3D could not write the mesh", path)
    return path, "open3d"
