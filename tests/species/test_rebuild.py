"""`species.rebuild`: a dictionary's own tree, grown with the rng its seed defines and meshed, in one call."""
from __future__ import annotations

import numpy as np
import pytest

import species


@pytest.fixture(scope="module")
def maple_params():
    return species.sample("maple", np.random.default_rng(4))


def test_rebuild_is_grow_with_the_dictionarys_own_rng_then_build_mesh(maple_params):
    skeleton, mesh = species.rebuild(maple_params)
    expected = species.grow(maple_params, species.rng_for(maple_params))
    for name, array in expected.to_arrays().items():
        np.testing.assert_array_equal(getattr(skeleton, name), array)
    assert mesh.to_glb() == species.build_mesh(expected, maple_params).to_glb()


def test_rebuild_names_the_mesh_without_touching_the_dictionary(maple_params):
    before = dict(maple_params)
    _, mesh = species.rebuild(maple_params, name="maple-0042")
    assert mesh.name == "maple-0042" and maple_params == before
    assert "maple-0042.obj" in mesh.to_obj()


def test_a_tree_over_max_nodes_is_refused_before_meshing(maple_params, monkeypatch):
    n_nodes = species.rebuild(maple_params)[0].n_nodes
    meshed = []
    monkeypatch.setattr("species.growth.build_mesh", lambda *a: meshed.append(a))
    with pytest.raises(species.TreeTooLargeError, match=f"skeleton has {n_nodes} nodes; allowed max_nodes = 10"):
        species.rebuild(maple_params, max_nodes=10)
    assert meshed == []


def test_every_generator_rebuilds_the_same_bytes_twice():
    for preset in ("palm", "sc_young_sapling", "lsystem_monopodial"):
        params = species.sample(preset, np.random.default_rng(1))
        assert species.rebuild(params)[1].to_glb() == species.rebuild(params)[1].to_glb()


def test_an_unknown_mesh_file_format_names_the_known_ones(maple_params):
    _, mesh = species.rebuild(maple_params)
    with pytest.raises(species.TreefarmError, match="mesh file format 'fbx' is unknown: allowed glb, obj"):
        mesh.export("fbx")
