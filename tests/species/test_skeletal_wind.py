"""Baked skeletal wind (species.studio.skeletal_wind): the joint hierarchy keeps to its budget and grows from the
trunk out, skins hold at most 4 weights that sum to 1 and blend across joints, the clip loops seamlessly and
follows the shader's lean and sway, and a still wind is the rest pose."""
from __future__ import annotations

import numpy as np
import pytest

import species
from species.meshing.gltf import z_up_to_y_up
from species.studio.skeletal_wind import (MAX_INFLUENCES, TRUNK_SEGMENTS, WIND_ACROSS, WIND_DIRECTION,
                                         WindClipSettings, joint_world_poses, shader_wind_offset, skin_weights,
                                         wind_clip, wind_rig)
from species.studio.wind import wind_attributes


@pytest.fixture(scope="module", params=["maple", "palm"])
def tree(request):
    """(skeleton, mesh) of one maple (many branches: the budget binds) and one palm (few: it does not)."""
    params = species.sample(request.param, np.random.default_rng(3))
    return species.rebuild(params, name=request.param)


def test_the_rig_keeps_to_its_budget_with_the_trunk_first_and_parents_before_children(tree):
    skeleton, _ = tree
    for budget in (TRUNK_SEGMENTS, 12, 64):
        rig = wind_rig(skeleton, budget)
        assert TRUNK_SEGMENTS <= rig.n_joints <= budget
        assert rig.names[:TRUNK_SEGMENTS] == tuple(f"trunk_{k}" for k in range(TRUNK_SEGMENTS))
        assert rig.parent[0] == -1 and all(0 <= p < j for j, p in enumerate(rig.parent) if j > 0)
        assert set(rig.level[TRUNK_SEGMENTS:].tolist()) <= {0, 1, 2}
        # A second-order joint hangs under its own branch's parent joint, never under the trunk.
        second = np.flatnonzero(rig.level == 2)
        assert (rig.level[rig.parent[second]] == 1).all()
    full = wind_rig(skeleton, 256)
    jointed = np.flatnonzero(full.own_joint >= 0)
    assert len(jointed) == full.n_joints - TRUNK_SEGMENTS  # every joint past the trunk is one LOD0 branch's


def test_a_budget_under_the_trunks_segments_is_refused(tree):
    with pytest.raises(ValueError, match="trunk"):
        wind_rig(tree[0], TRUNK_SEGMENTS - 1)


def test_skins_have_at_most_four_weights_summing_to_one_and_blend_across_joints(tree):
    skeleton, mesh = tree
    rig = wind_rig(skeleton, 64)
    bark = mesh.bark
    joints, weights = skin_weights(rig, bark.vertices, bark.attributes["branch"])
    assert joints.shape == weights.shape == (bark.n_vertices, MAX_INFLUENCES)
    assert np.allclose(weights.sum(axis=1), 1.0, atol=1e-6) and (weights >= 0).all()
    assert joints.max() < rig.n_joints
    assert (np.diff(weights, axis=1) <= 1e-7).all()  # heaviest first
    # Blending: some vertices share two or more joints (trunk segments, a branch's first quarter) ...
    assert ((weights > 0.05).sum(axis=1) >= 2).mean() > 0.05
    # ... and vertices at one place (a tube's seam, a branch's first ring on its parent) move as one: no cracks.
    _, first, group = np.unique(np.round(bark.vertices, 5), axis=0, return_index=True, return_inverse=True)
    group = group.reshape(-1)
    dense = np.zeros((bark.n_vertices, rig.n_joints))
    np.add.at(dense, (np.arange(bark.n_vertices)[:, None], joints), weights)
    assert np.abs(dense - dense[first[group]]).max() < 1e-5


def test_the_clip_loops_and_a_still_wind_is_the_rest_pose(tree):
    rig = wind_rig(tree[0], 64)
    clip = wind_clip(rig, WindClipSettings(period_s=4.0))
    assert clip.duration == pytest.approx(4.0) and clip.rotations.shape == (len(clip.times), rig.n_joints, 4)
    assert np.array_equal(clip.rotations[0], clip.rotations[-1]) and np.array_equal(clip.impostor[0],
                                                                                   clip.impostor[-1])
    assert np.allclose(np.linalg.norm(clip.rotations, axis=2), 1.0)
    assert np.abs(clip.rotations[1:] - clip.rotations[:-1]).max() > 1e-4  # it moves
    still = wind_clip(rig, WindClipSettings(strength=0.0))
    assert np.allclose(still.rotations, [0.0, 0.0, 0.0, 1.0]) and np.allclose(still.impostor, [0, 0, 0, 1])


def test_the_clip_follows_the_shaders_lean_and_first_order_sway(tree):
    # At the trunk's top and at every first-order branch tip, where the clip's joints put the point and where
    # the shader (with the clip's whole-cycle rates) offsets it agree, for the sway across the branch (a turn
    # keeps a branch's length, so the part along it is left out).
    skeleton, _ = tree
    settings = WindClipSettings(strength=1.0)
    rig = wind_rig(skeleton, 64)
    clip = wind_clip(rig, settings)
    world, position = joint_world_poses(rig, clip.rotations)
    first = np.flatnonzero(rig.level == 1)
    joints = np.concatenate([[TRUNK_SEGMENTS - 1], first])
    rest_tips = rig.position[joints] + rig.direction[joints] * rig.reach[joints, None]
    moved = np.einsum("kjab,jb->kja", world[:, joints], rest_tips - rig.position[joints]) + position[:, joints]
    branch = np.concatenate([[0], [int(np.flatnonzero(rig.own_joint == j)[0]) for j in first]])
    wind, pivot = wind_attributes(skeleton, rest_tips, branch)
    expected = shader_wind_offset(rest_tips, wind, pivot, clip.times, settings, rig.height)
    error = moved - rest_tips - expected
    across = error - np.einsum("kja,ja->kj", error, rig.direction[joints])[..., None] * rig.direction[joints]
    amplitude = np.linalg.norm(expected, axis=2).max(axis=0)
    share = np.linalg.norm(across, axis=2).max(axis=0) / amplitude
    assert share[0] < 0.05 and np.median(share) < 0.15 and np.percentile(share, 90) < 0.4


def test_the_wind_blows_where_the_pages_shader_blows_it():
    # wind_example.html: windDirection = normalize(1, 0.3) in glTF's ground plane (x, z), and the swing's
    # across = (-windDirection.y, 0, windDirection.x), both Y up.
    downwind, across = z_up_to_y_up(np.stack([WIND_DIRECTION, WIND_ACROSS]))
    assert np.allclose(downwind, np.array([1.0, 0.0, 0.3]) / np.hypot(1.0, 0.3), atol=1e-7)
    assert np.allclose(across, [-downwind[2], 0.0, downwind[0]], atol=1e-7)
