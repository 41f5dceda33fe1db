"""Specification of rigid branch moves (farm.modelling.branch_moves): subtrees move whole; the hull guard refuses
a move that makes moved branches touch the others."""
from __future__ import annotations

import numpy as np
import pytest

from farm.modelling.branch_moves import guarded_move, move_branches, MoveRefused, subtree_branches, swipe_angle
from species.geometry.rotations import rot_axis

TRUNK = (np.linspace([0, 0, 0], [0, 0, 3.0], 31), -1)
LEFT = (np.linspace([0, 0, 1.5], [-1.0, 0, 2.5], 15), 0)
LEFT_TWIG = (np.linspace([-0.6, 0, 2.1], [-0.6, 0.5, 2.6], 8), 1)
RIGHT = (np.linspace([0, 0, 2.0], [1.0, 0, 2.8], 15), 0)
BRANCHES = [TRUNK, LEFT, LEFT_TWIG, RIGHT]


def _turn_about_z(angle: float) -> np.ndarray:
    return rot_axis(np.array([0.0, 0.0, 1.0]), angle)[0]


def test_a_subtree_is_the_branch_and_all_that_grows_from_it():
    assert subtree_branches(BRANCHES, 1) == [1, 2]
    assert subtree_branches(BRANCHES, 0) == [0, 1, 2, 3]


def test_a_move_carries_the_subtree_rigidly_and_leaves_the_rest():
    turn = _turn_about_z(np.pi / 2)
    moved = guarded_move(BRANCHES, 1, turn, pivot=LEFT[0][0])
    assert np.array_equal(moved[0][0], TRUNK[0]) and np.array_equal(moved[3][0], RIGHT[0])
    for k in (1, 2):
        assert np.allclose(moved[k][0], (BRANCHES[k][0] - LEFT[0][0]) @ turn.T + LEFT[0][0])
    gap = moved[2][0][:, None, :] - moved[1][0][None, :, :]
    assert np.allclose(np.linalg.norm(gap, axis=2), np.linalg.norm(LEFT_TWIG[0][:, None] - LEFT[0][None], axis=2))


def test_a_move_onto_another_branch_is_refused():
    with pytest.raises(MoveRefused, match="1 with 3"):
        guarded_move(BRANCHES, 1, _turn_about_z(np.pi), pivot=LEFT[0][0], translation=[0, 0, 0.5])
    with pytest.raises(MoveRefused, match="with 0"):
        guarded_move(BRANCHES, 3, translation=[-0.5, 0, 0])  # dragged across the trunk


@pytest.mark.parametrize("kwargs, message", [
    ({"rotation": np.diag([1.0, 1.0, -1.0])}, "rotation"),
    ({"translation": [np.nan, 0, 0]}, "finite"),
])
def test_bad_moves_are_refused(kwargs, message):
    with pytest.raises(MoveRefused, match=message):
        move_branches(BRANCHES, 1, **kwargs)
    with pytest.raises(MoveRefused, match="does not exist"):
        subtree_branches(BRANCHES, 9)


def test_a_thumb_swipe_turns_by_the_angle_it_sweeps_round_the_centre():
    assert swipe_angle([1, 0], [0, 1]) == pytest.approx(np.pi / 2)
    assert swipe_angle([0, 1], [1, 0]) == pytest.approx(-np.pi / 2)
    assert swipe_angle([255, 127.5], [127.5, 255], centre=(127.5, 127.5)) == pytest.approx(np.pi / 2)  # the pad
    assert swipe_angle([0.5, 0.5], [-0.5, -0.5]) == pytest.approx(np.pi)
    assert swipe_angle([0, 0], [1, 0]) == 0.0
