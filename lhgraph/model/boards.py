"""Built-in photodiode board geometries (board frame, metres).

Both boards use the same 32-diode footprint: a 6 x 6 grid at 24 mm pitch (x, y in
{-60, -36, -12, 12, 36, 60} mm) minus the 4 corners, about 12 x 12 cm, ids numbered row by
row from (-x, -y) to (+x, +y).

- ``paper32``: the paper's flat board; diodes in the board's x-y plane, normals +z, origin
  at the centre of the grid.
- ``pyramid32``: the same footprint lifted onto a low square pyramid whose 4 faces are
  tilted by ``tilt_deg`` (30 by default) toward +x, +y, -x and -y. A diode sits on the face
  of its dominant coordinate (``|x| > |y|`` -> an x face); the 8 diagonal diodes are shared
  out so that every face holds 8 diodes and a 90-degree turn about z maps the board onto
  itself. Heights follow the pyramid surface ``z = (60 mm - max(|x|, |y|)) tan(tilt)``,
  then the whole board is shifted so the diodes' centroid is the origin. Stations far off
  the board's normal (e.g. facing each other 160 degrees apart) still see one or two faces.
- ``crazyflie_deck``: Bitcraze's Lighthouse deck on a Crazyflie, 4 diodes in the Crazyflie's
  body frame (x forward, y left, z up; origin at the deck's centre), 30 mm apart along x and
  15 mm along y, normals +z; ids 0-3 at (x, y) = (-, +), (-, -), (+, +), (+, -).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from lhgraph.errors import InputError
from lhgraph.model.board import Board, load_board, make_board

PITCH_M = 0.024
GRID_N = 6


def grid_positions() -> np.ndarray:
    """x-y positions (m) of the 32-diode footprint ``(32, 2)``, row by row."""
    coords = (np.arange(GRID_N) - (GRID_N - 1) / 2) * PITCH_M
    y, x = np.meshgrid(coords, coords, indexing="ij")
    xy = np.round(np.stack([x.ravel(), y.ravel()], axis=1), 9)
    edge = np.abs(coords).max() - 1e-9
    corner = (np.abs(xy[:, 0]) > edge) & (np.abs(xy[:, 1]) > edge)
    return xy[~corner]


def paper_board() -> Board:
    """The paper's flat 32-diode board: grid in the x-y plane, normals +z, origin at centre."""
    xy = grid_positions()
    positions = np.column_stack([xy, np.zeros(len(xy))])
    normals = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    return make_board(positions, normals, name="paper32")


def pyramid_board(tilt_deg: float = 30.0) -> Board:
    """The 32-diode footprint on a square pyramid with faces tilted ``tilt_deg`` (see module)."""
    xy = grid_positions()
    x, y = xy[:, 0], xy[:, 1]
    ax, ay = np.abs(x), np.abs(y)
    # Diagonal diodes go to the face a quarter turn "behind" them (counter-clockwise order
    # +x, +y, -x, -y), which keeps the assignment symmetric under a 90-degree turn.
    diagonal = np.isclose(ax, ay)
    on_x = (ax > ay) | (diagonal & (np.sign(x) == np.sign(y)))
    tilt = np.radians(tilt_deg)
    sign = np.where(on_x, np.sign(x), np.sign(y))
    normals = np.zeros((len(xy), 3))
    normals[:, 0] = np.where(on_x, sign * np.sin(tilt), 0.0)
    normals[:, 1] = np.where(on_x, 0.0, sign * np.sin(tilt))
    normals[:, 2] = np.cos(tilt)
    rim = np.abs(grid_positions()).max()
    z = (rim - np.maximum(ax, ay)) * np.tan(tilt)
    positions = np.column_stack([xy, z])
    positions = np.round(positions - positions.mean(axis=0), 9)
    return make_board(positions, normals, name="pyramid32")


DECK_HALF_X_M = 0.015
DECK_HALF_Y_M = 0.0075


def crazyflie_deck() -> Board:
    """The Crazyflie Lighthouse deck's 4 diodes (see module docstring), Crazyflie body frame."""
    sx = np.array([-1.0, -1.0, 1.0, 1.0])
    sy = np.array([1.0, -1.0, 1.0, -1.0])
    positions = np.column_stack([sx * DECK_HALF_X_M, sy * DECK_HALF_Y_M, np.zeros(4)])
    return make_board(positions, np.tile([0.0, 0.0, 1.0], (4, 1)), name="crazyflie_deck")


BUILTIN_BOARDS: dict[str, Callable[[], Board]] = {
    "paper32": paper_board,
    "pyramid32": pyramid_board,
    "crazyflie_deck": crazyflie_deck,
}


def board_by_name(name: str, base_dir: str | Path | None = None,
                  source: str | Path | None = None, where: str | None = None) -> Board:
    """A built-in board by name, else a board TOML path (relative to ``base_dir``).

    Unknown names raise InputError naming ``source`` and ``where`` (the config key).
    """
    if name in BUILTIN_BOARDS:
        return BUILTIN_BOARDS[name]()
    path = Path(name)
    if not path.is_absolute() and base_dir is not None:
        path = Path(base_dir) / path
    if path.suffix != ".toml" or not path.is_file():
        raise InputError(
            f"board {name!r} is neither a built-in board ({', '.join(BUILTIN_BOARDS)}) "
            "nor an existing .toml file", source, where)
    return load_board(path)
