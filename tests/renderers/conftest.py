"""Shared fixtures for the renderer tests: one ViewRenderer (one GL context) and two small test trees."""
from __future__ import annotations

import numpy as np
import pytest

from tree_factory import make_tree

SIZE = 160


@pytest.fixture(scope="session")
def view_renderer():
    from renderers import ViewRenderer

    renderer = ViewRenderer(SIZE)
    yield renderer
    renderer.close()


@pytest.fixture(scope="session")
def tree():
    return make_tree(np.random.default_rng(7))


@pytest.fixture(scope="session")
def other_tree():
    return make_tree(np.random.default_rng(11), n_branches=5)


@pytest.fixture(scope="session")
def all_outputs(view_renderer, tree):
    """Every output of every view of the tree, for the tsn4 and two-view rigs: {rig: [RenderedView]}."""
    from renderers import OUTPUTS

    mesh, skeleton = tree
    return {rig: view_renderer.render(mesh, skeleton, rig, list(OUTPUTS), np.random.default_rng(3))
            for rig in ("tsn4", "two-view")}
