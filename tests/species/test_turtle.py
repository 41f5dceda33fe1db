"""Specification of the 3D turtle: known end points, bracket state, widths, orders, tropism, leaves."""
import numpy as np
import pytest

from species.lsystem.rewrite import rewrite
from species.lsystem.turtle import initial_frame, interpret, leaf_cards


def draw(text, angle=30.0, step=1.0, width=0.2, width_ratio=0.5, **kwargs):
    modules = rewrite(text, [], 0, np.random.default_rng(0))
    return interpret(modules, angle=angle, step=step, width=width, width_ratio=width_ratio,
                     rng=np.random.default_rng(0), **kwargs)


def test_start_frame_is_right_handed_with_heading_up():
    heading, left, up = initial_frame().T
    assert np.allclose(heading, [0, 0, 1]) and np.allclose(np.cross(heading, left), up)


def test_forward_turn_left_90_forward_ends_at_known_point():
    path = draw("F+(90)F", step=2.0)
    assert np.allclose(path.positions, [[0, 0, 0], [0, 0, 2], [0, 2, 2]])


def test_turn_right_mirrors_turn_left():
    left, right = draw("F+(90)F").positions[-1], draw("F-(90)F").positions[-1]
    assert np.allclose(left * [1, -1, 1], right)


def test_pitch_up_heads_toward_up_vector_and_down_away():
    assert np.allclose(draw("F&(90)F").positions[-1], [-1, 0, 1])
    assert np.allclose(draw("F^(90)F").positions[-1], [1, 0, 1])


def test_roll_turns_the_following_left_turn_into_a_pitch():
    rolled = draw("F\\(90)+(90)F").positions[-1]
    assert np.allclose(rolled, draw("F&(90)F").positions[-1])


def test_turn_around_reverses_heading():
    assert np.allclose(draw("F+(45)|F").positions[-1], draw("F-(135)F").positions[-1])


def test_bare_symbols_use_angle_and_step():
    path = draw("F+F", angle=30.0, step=0.5)
    assert np.allclose(path.positions[-1], [0, 0.5 * np.sin(np.radians(30)), 0.5 + 0.5 * np.cos(np.radians(30))])


def test_bracket_restores_position_and_heading():
    path = draw("F[+(90)F]F")
    assert np.allclose(path.positions[3], [0, 0, 2])
    assert path.parent.tolist() == [-1, 0, 1, 1]


def test_parameterised_forward_scales_step():
    assert np.allclose(draw("F(1.2)", step=0.5).positions[-1], [0, 0, 0.6])


def test_bang_scales_width_in_scope_only():
    path = draw("F!(0.8)F[!F]F", width=0.2, width_ratio=0.5)
    assert np.allclose(path.width, [0.2, 0.2, 0.16, 0.08, 0.16])


def test_parents_precede_children():
    modules = rewrite("X", ["X -> F[-X][+X]"], 5, np.random.default_rng(0))
    path = interpret(modules, angle=30, step=1, width=0.1, width_ratio=0.7, rng=np.random.default_rng(0))
    assert np.all(path.parent[1:] < np.arange(1, len(path.parent)))
    assert len(path.positions) == 1 + 31


def test_order_rises_by_one_per_branch_even_through_nested_brackets():
    path = draw("F[[+F]-F]F")
    assert path.order.tolist() == [0, 0, 1, 1, 0]


def test_move_without_drawing_adds_no_node_but_moves():
    path = draw("FfF")
    assert len(path.positions) == 3 and np.allclose(path.positions[-1], [0, 0, 3])
    assert path.parent.tolist() == [-1, 0, 1]


def test_downward_tropism_bends_a_horizontal_branch_down():
    straight = draw("+(90)FFFF").positions[-1]
    drooping = draw("+(90)FFFF", tropism=(0, 0, -0.3)).positions[-1]
    assert drooping[2] < straight[2] - 0.5


def test_tropism_keeps_frames_orthonormal():
    path = draw("+(60)FFFFFF/(30)&(20)FFF", tropism=(0.1, 0, -0.3))
    gram = np.einsum("nji,njk->nik", path.frames, path.frames)
    assert np.allclose(gram, np.eye(3), atol=1e-9)


def test_angle_jitter_perturbs_turns_reproducibly():
    modules = rewrite("F+F+F", [], 0, np.random.default_rng(0))
    kwargs = dict(angle=30, step=1, width=0.1, width_ratio=0.7, angle_jitter=5.0)
    first = interpret(modules, rng=np.random.default_rng(3), **kwargs).positions
    again = interpret(modules, rng=np.random.default_rng(3), **kwargs).positions
    other = interpret(modules, rng=np.random.default_rng(4), **kwargs).positions
    assert np.array_equal(first, again) and not np.allclose(first, other)


def test_leaf_symbol_hangs_from_the_last_node_with_its_frame():
    path = draw("F[+(90)L(2)]F")
    assert path.leaf_node.tolist() == [1] and path.leaf_scale.tolist() == [2.0]
    assert np.allclose(path.leaf_frames[0][:, 0], [0, 1, 0])


def test_leaf_cards_are_rigid_scaled_frames_at_their_stems():
    frames = np.repeat(initial_frame()[None], 3, axis=0)
    cards = leaf_cards(np.zeros((3, 3)), frames, 0.1, 0.05, 30.0, np.array([0.0, 1.0, 2.0]))
    along = cards[:, :3, 2] / 0.1
    side = cards[:, :3, 0] / 0.05
    assert np.allclose(np.linalg.norm(along, axis=1), 1, atol=1e-6)
    assert np.allclose(np.einsum("ij,ij->i", along, side), 0, atol=1e-6)
    assert np.allclose(np.degrees(np.arccos(along[:, 2])), 30, atol=1e-4)
