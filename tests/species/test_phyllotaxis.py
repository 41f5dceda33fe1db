"""Specification of phyllotaxis twigs: patterns, counts, attachment at the tips, leaves, determinism."""
import numpy as np
import pytest

from species.errors import ParameterError
from species.lsystem.phyllotaxis import PATTERNS, add_twigs
from species.skeleton import Skeleton

# Nodes (F count) and leaf cards (terminal F count) of one twig of each pattern.
COUNTS = {"opposite": (10, 7), "alternate": (9, 5), "whorled": (16, 13)}


def y_tree() -> Skeleton:
    positions = np.array([[0, 0, 0], [0, 0, 1], [0.5, 0, 1.5], [-0.5, 0.2, 1.6]], float)
    return Skeleton(positions, [-1, 0, 1, 1], [0.05, 0.04, 0.01, 0.01], [0, 0, 1, 1])


@pytest.mark.parametrize("pattern", sorted(PATTERNS))
def test_each_tip_gets_one_twig_with_a_card_per_terminal_shoot(pattern):
    grown = add_twigs(y_tree(), pattern, np.random.default_rng(0))
    nodes, cards = COUNTS[pattern]
    assert len(grown) == 4 + 2 * nodes and grown.n_leaves == 2 * cards
    assert np.all(grown.parent[1:] < np.arange(1, len(grown)))


def test_twigs_start_at_the_old_tips_and_old_nodes_are_kept():
    tree = y_tree()
    grown = add_twigs(tree, "opposite", np.random.default_rng(0))
    assert np.array_equal(grown.positions[:4], tree.positions)
    assert sorted(grown.parent[4:][grown.parent[4:] < 4].tolist()) == [2, 3]
    assert set(grown.tips.tolist()).isdisjoint({2, 3})


def test_twig_axis_continues_the_tip_direction():
    tree = y_tree()
    grown = add_twigs(tree, "alternate", np.random.default_rng(0), scale_jitter=0.0)
    first = int(np.flatnonzero(grown.parent == 2)[0])
    along = grown.positions[first] - grown.positions[2]
    tip_edge = tree.positions[2] - tree.positions[1]
    assert np.allclose(along / np.linalg.norm(along), tip_edge / np.linalg.norm(tip_edge), atol=1e-6)
    assert np.isclose(np.linalg.norm(along), 0.04)


def test_twig_axis_keeps_the_branch_order_and_side_shoots_add_one():
    grown = add_twigs(y_tree(), "opposite", np.random.default_rng(0))
    assert set(grown.order[4:].tolist()) == {1, 2}
    assert grown.order[grown.continuation[2]] == 1


def test_twig_radii_taper_from_the_tip_radius():
    grown = add_twigs(y_tree(), "whorled", np.random.default_rng(0))
    assert np.all(grown.radius[4:] <= 0.01 + 1e-7) and np.all(grown.radius[4:] > 0)


def test_twigs_are_seeded():
    a = add_twigs(y_tree(), "opposite", np.random.default_rng(3))
    b = add_twigs(y_tree(), "opposite", np.random.default_rng(3))
    c = add_twigs(y_tree(), "opposite", np.random.default_rng(4))
    assert np.array_equal(a.positions, b.positions) and not np.allclose(a.positions, c.positions)


def test_leaf_cards_hang_from_twig_nodes():
    grown = add_twigs(y_tree(), "opposite", np.random.default_rng(0))
    assert grown.leaf_node.min() >= 4
    assert np.allclose(grown.leaves[:, :3, 3], grown.positions[grown.leaf_node], atol=1e-6)


def test_unknown_pattern_is_rejected_with_the_known_ones():
    with pytest.raises(ParameterError, match="opposite"):
        add_twigs(y_tree(), "spiral", np.random.default_rng(0))
