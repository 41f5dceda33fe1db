"""Specification of the rigid-move guard (farm.modelling.hull_contact): convex hulls in contact exactly when they
overlap or touch; apart by a hair is apart; flat and collinear sets too."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linprog

from farm.modelling.hull_contact import hull_distance, HullError, hulls_overlap

CUBE = np.array(list(itertools.product([0.0, 1.0], repeat=3)))
SQUARE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
HAIR = 1e-6  # metres: a micrometre apart


@pytest.mark.parametrize("offset, contact", [
    ([0.5, 0.2, 0.1], True),             # overlapping
    ([1.0, 0.3, 0.2], True),             # touching face to face
    ([1.0, 1.0, 0.5], True),             # touching along an edge
    ([1.0, 1.0, 1.0], True),             # touching at a corner
    ([1.0 + HAIR, 0.3, 0.2], False),     # apart by a hair
    ([1.0 + HAIR, 1.0, 1.0], False),
    ([1.0, 1.0 + HAIR, 1.0 + HAIR], False),
])
def test_cubes_are_in_contact_exactly_when_they_overlap_or_touch(offset, contact):
    assert hulls_overlap(CUBE, CUBE + offset) is contact


def test_the_distance_between_hulls_is_exact():
    assert hull_distance(CUBE, CUBE + [1 + HAIR, 0.3, 0.2]) == pytest.approx(HAIR, rel=1e-6)
    assert hull_distance(CUBE, CUBE + [2, 2, 2]) == pytest.approx(np.sqrt(3), rel=1e-12)
    assert hulls_overlap(CUBE, CUBE + [1 + HAIR, 0, 0], tolerance=2 * HAIR)


def test_flat_and_collinear_sets():
    assert hulls_overlap(SQUARE, SQUARE + [0.5, 0.5, 0])          # coplanar squares overlapping
    assert not hulls_overlap(SQUARE, SQUARE + [0, 0, 1e-7])       # parallel, a hair above
    rising, crossing = np.array([[0, 0, 0], [1, 1, 1.0]]), np.array([[1, 0, 0], [0, 1, 1.0]])
    assert hulls_overlap(rising, crossing)                        # segments crossing at their middles
    assert hull_distance(rising, crossing + [0, 0, HAIR]) == pytest.approx(HAIR / np.sqrt(2), rel=1e-6)
    assert hulls_overlap(np.zeros((1, 3)), SQUARE) and not hulls_overlap(np.array([[0.5, 0.5, HAIR]]), SQUARE)
    assert hulls_overlap(np.array([[0.5, 0.5, 0.0]]), CUBE)       # a point on a face


def _lp_intersect(a: np.ndarray, b: np.ndarray) -> bool:
    """An independent answer: some convex combination of a equals one of b (an LP feasibility problem)."""
    equality = np.zeros((5, len(a) + len(b)))
    equality[:3, : len(a)], equality[:3, len(a):] = a.T, -b.T
    equality[3, : len(a)], equality[4, len(a):] = 1, 1
    return linprog(np.zeros(len(a) + len(b)), A_eq=equality, b_eq=[0, 0, 0, 1, 1], bounds=(0, None)).status == 0


def test_random_sets_agree_with_a_linear_program():
    rng = np.random.default_rng(7)
    answers = []
    for _ in range(60):
        a = rng.normal(size=(int(rng.integers(1, 25)), 3))
        b = rng.normal(size=(int(rng.integers(1, 25)), 3)) + rng.normal(size=3) * 2
        answers.append(hulls_overlap(a, b))
        assert answers[-1] == _lp_intersect(a, b)
    assert 10 < sum(answers) < 50  # both outcomes exercised


@pytest.mark.parametrize("a, b, tolerance", [
    (np.zeros((0, 3)), CUBE, 0.0), (np.zeros((3, 2)), CUBE, 0.0), (np.full((2, 3), np.inf), CUBE, 0.0),
    (CUBE, CUBE, -1.0)])
def test_bad_point_sets_are_refused(a, b, tolerance):
    with pytest.raises(HullError):
        hulls_overlap(a, b, tolerance)
