"""Built-in boards: geometry facts and the shipped board files."""

from pathlib import Path

import numpy as np
import pytest

from lhgraph.errors import InputError
from lhgraph.model.board import load_board
from lhgraph.model.boards import BUILTIN_BOARDS, board_by_name, paper_board, pyramid_board

CONFIGS = Path(__file__).resolve().parent.parent / "configs" / "boards"


def test_paper_board_is_flat_grid_facing_z():
    b = paper_board()
    assert len(b.ids) == 32 and len(set(b.ids.tolist())) == 32
    assert b.is_planar()
    np.testing.assert_allclose(b.normals, np.tile([0, 0, 1.0], (32, 1)))
    np.testing.assert_allclose(b.positions.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.ptp(b.positions[:, :2], axis=0), [0.12, 0.12])
    d = np.linalg.norm(b.positions[:, None] - b.positions[None], axis=-1)
    assert np.isclose(d[d > 0].min(), 0.024)
    # the 4 corners of the 6x6 grid are missing
    assert not np.any(np.all(np.isclose(np.abs(b.positions[:, :2]), 0.06), axis=1))


def test_pyramid_board_faces_and_symmetry():
    b = pyramid_board(30.0)
    assert len(b.ids) == 32 and not b.is_planar()
    np.testing.assert_allclose(b.positions.mean(axis=0), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(b.normals, axis=1), 1.0)
    np.testing.assert_allclose(b.normals[:, 2], np.cos(np.radians(30)))
    faces, counts = np.unique(np.round(b.normals, 6), axis=0, return_counts=True)
    assert len(faces) == 4 and np.all(counts == 8)
    # a quarter turn about z maps the board (positions with their normals) onto itself
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    key = np.round(np.hstack([b.positions, b.normals]), 6)
    turned = np.round(np.hstack([b.positions @ Rz.T, b.normals @ Rz.T]), 6)
    assert {tuple(r) for r in key} == {tuple(r) for r in turned}
    # same footprint as the flat board, and every diode lies on its face's plane
    np.testing.assert_allclose(b.positions[:, :2], paper_board().positions[:, :2])
    for face in faces:
        on_face = np.all(np.isclose(b.normals, face, atol=1e-6), axis=1)
        offsets = b.positions[on_face] @ face
        np.testing.assert_allclose(offsets, offsets[0], atol=1e-8)


@pytest.mark.parametrize("name", sorted(BUILTIN_BOARDS))
def test_board_files_equal_builtin(name):
    expected = BUILTIN_BOARDS[name]()
    loaded = load_board(CONFIGS / f"{name}.toml")
    assert loaded.name == expected.name
    np.testing.assert_array_equal(loaded.ids, expected.ids)
    np.testing.assert_allclose(loaded.positions, expected.positions, rtol=0, atol=1e-15)
    np.testing.assert_allclose(loaded.normals, expected.normals, rtol=0, atol=1e-15)


def test_board_by_name(tmp_path):
    assert board_by_name("pyramid32").name == "pyramid32"
    loaded = board_by_name("paper32.toml", CONFIGS)
    np.testing.assert_allclose(loaded.positions, paper_board().positions)
    with pytest.raises(InputError, match=r"cfg\.toml:board: board 'nope'"):
        board_by_name("nope", tmp_path, "cfg.toml", "board")


def test_crazyflie_deck_geometry():
    b = board_by_name("crazyflie_deck")
    assert b.ids.tolist() == [0, 1, 2, 3] and b.is_planar()
    # 30 mm apart along x, 15 mm along y, around the origin; ids (-,+), (-,-), (+,+), (+,-)
    np.testing.assert_allclose(np.sign(b.positions[:, :2]), [[-1, 1], [-1, -1], [1, 1], [1, -1]])
    np.testing.assert_allclose(np.ptp(b.positions, axis=0), [0.030, 0.015, 0.0])
    np.testing.assert_allclose(b.normals, np.tile([0, 0, 1.0], (4, 1)))
