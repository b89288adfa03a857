"""A board's width and height fitted to its face, proud of the wall (engine/detection/faces.py)."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.faces import face_cells, face_extent, fit_faces
from engine.detection.settings import DetectionSettings
from tiles.classes import ELEMENT_CLASSES

BOARD = ELEMENT_CLASSES.index("board")
EXTENT = np.array([5.0, 8.0, 3.0])


def _wall_with_board(rng, u0, u1, z0, z1, proud=0.02, noise=0.003, n=80000):
    """The wall x = 0.05 of a room (x grows into the room) scanned with ``noise``, a board ``proud`` metres in
    front of it over y in [u0, u1], z in [z0, z1], and a chair's back 0.4 m in front beside the board."""
    face = rng.uniform([0.0, 0.0, 0.0], [0.0, 8.0, 3.0], (n, 3))
    on = (face[:, 1] > u0) & (face[:, 1] < u1) & (face[:, 2] > z0) & (face[:, 2] < z1)
    face[:, 0] = 0.05 + np.where(on, proud, 0.0) + rng.normal(0, noise, n)
    chair = rng.uniform([0.45, u1 + 0.2, 0.4], [0.5, u1 + 0.7, 1.0], (3000, 3))
    return np.concatenate([face, chair])


def _query(points):
    return lambda lo, hi: points[np.all((points >= np.asarray(lo) - 0.1) & (points <= np.asarray(hi) + 0.1), axis=1)]


@pytest.mark.parametrize("proud,noise", [(0.02, 0.003), (0.01, 0.002), (0.08, 0.005)])
def test_a_board_box_takes_the_width_and_height_of_its_face(proud, noise):
    rng = np.random.default_rng(0)
    pts = _wall_with_board(rng, 2.0, 4.6, 0.9, 2.05, proud, noise)  # a 2.6 m board
    # the detector's box after the depth fit: a training board's size (1.7 x 1.1 m), off its place
    lo, hi = np.array([[0.05, 2.5, 1.0]]), np.array([[0.05 + proud + 0.005, 4.2, 2.1]])
    depth = (lo[0, 0], hi[0, 0])
    assert fit_faces(lo, hi, np.array([BOARD]), _query(pts), ("board",), 1.0, EXTENT)[0] == 1
    assert np.allclose([lo[0, 1], hi[0, 1], lo[0, 2], hi[0, 2]], [2.0, 4.6, 0.9, 2.05], atol=0.06)
    assert (lo[0, 0], hi[0, 0]) == depth  # the depth is left as it is


def test_a_face_that_runs_on_or_none_at_all_leaves_the_box():
    rng = np.random.default_rng(1)
    pts = _wall_with_board(rng, 0.5, 7.5, 0.9, 2.05)  # proud of the wall beyond the search on both sides
    lo, hi = np.array([[0.05, 2.5, 1.0]]), np.array([[0.075, 4.2, 2.1]])
    _, bare = fit_faces(lo, hi, np.array([BOARD]), _query(pts), ("board",), 1.0, EXTENT)
    # the face beside the box is the board's, taken for the wall's plane: nothing stands out of it, the box stays
    # and is called bare (the rule's limit: a board longer than its box by face-grow on both sides is not kept)
    assert lo[0, 1] == 2.5 and hi[0, 1] == 4.2 and bare[0]
    pts = _wall_with_board(rng, 6.0, 7.0, 0.9, 2.05)  # the board is elsewhere: a bare wall under the box
    lo, hi = np.array([[0.05, 2.5, 1.0]]), np.array([[0.075, 4.2, 2.1]])
    done, bare = fit_faces(lo, hi, np.array([BOARD]), _query(pts), ("board",), 1.0, EXTENT)
    assert done == 0 and bare[0]
    assert np.array_equal(lo, [[0.05, 2.5, 1.0]]) and np.array_equal(hi, [[0.075, 4.2, 2.1]])
    # other classes are not touched
    pts = _wall_with_board(rng, 2.0, 4.6, 0.9, 2.05)
    done, bare = fit_faces(lo, hi, np.array([ELEMENT_CLASSES.index("door")]), _query(pts), ("board",), 1.0, EXTENT)
    assert done == 0 and not bare[0]


def test_face_cells_and_extent():
    along = np.repeat(np.arange(4), 4)
    up = np.zeros(16, np.int64)
    front = np.array([0.02] * 4 + [0.02, 0.02, 0.0, 0.0] + [0.0] * 4 + [0.02] * 4)
    cells = face_cells(along, up, front, 0.01, (4, 1))
    assert cells[:, 0].tolist() == [True, False, False, True]  # half proud is not most
    assert face_extent(cells, (slice(0, 2), slice(0, 1))) == (0, 1, 0, 1)
    assert face_extent(cells, (slice(1, 3), slice(0, 1))) is None


def test_face_settings_are_validated():
    assert DetectionSettings.from_config(face_classes="board").face_classes == ("board",)
    with pytest.raises(ValueError, match="face-grow"):
        DetectionSettings.from_config(face_grow=-1.0)
    with pytest.raises(ValueError, match="face-classes"):
        DetectionSettings.from_config(face_classes="boards")


def test_a_board_on_a_stand_with_no_wall_beside_is_not_bare():
    rng = np.random.default_rng(3)
    panel = rng.uniform([2.0, 3.0, 0.8], [2.02, 4.5, 2.0], (20000, 3))  # a board in the room, away from any wall
    legs = rng.uniform([1.9, 3.0, 0.0], [2.1, 4.5, 0.02], (2000, 3))
    lo, hi = np.array([[2.0, 3.1, 0.9]]), np.array([[2.03, 4.4, 1.9]])
    _, bare = fit_faces(lo, hi, np.array([BOARD]), _query(np.concatenate([panel, legs])), ("board",), 1.0, EXTENT)
    assert not bare[0]
