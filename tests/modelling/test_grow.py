"""Specification of growth in a hand-made model (farm.modelling.grow, brush): inside the lobes, from the drawn
branches, into painted markers; deterministic; bad models refused."""
from __future__ import annotations

import numpy as np
import pytest

import species
from farm.modelling.brush import brush_markers, BrushError
from farm.modelling.grow import (branch_guide, colonization_presets, grow_model, model_params, model_space,
                                 MIN_PERCEIVED, ModelError, perceived_markers,
                                 perception_at_budget)
from farm.modelling.lobes import lobe_mesh
from scipy.spatial import cKDTree

from species.colonization import MeshSpace, SCHEMA
from species.errors import ParameterError

FAST = {"max_markers": 1500, "iterations": 15}
TRUNK = (np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.2]]), -1)
LIMB = (np.array([[0.0, 0.0, 0.9], [0.5, 0.0, 1.4]]), 0)
PAINT_PATH = np.array([[1.05, 0.0, 1.6], [1.4, 0.0, 1.8]])


def _ring(radius: float, z: float, count: int = 32) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, count, endpoint=False)
    return np.stack([radius * np.cos(t), radius * np.sin(t), np.full(count, z)], axis=1)


@pytest.fixture(scope="module")
def lobe():
    return lobe_mesh([_ring(0.5, 1.0), _ring(0.8, 1.5), _ring(0.5, 2.1)])


def _grow(lobe, seed=0, branches=(TRUNK, LIMB), markers=None, **kwargs):
    return grow_model([lobe], list(branches), markers, "sc_round_maple", FAST, np.random.default_rng(seed), **kwargs)


def test_the_menu_lists_the_colonization_presets():
    names = colonization_presets()
    assert names == sorted(p.name for p in species.list_presets("colonization")) and "sc_round_maple" in names


def test_same_generator_same_skeleton_bytes(lobe):
    first, second = _grow(lobe, 3), _grow(lobe, 3)
    assert first.positions.tobytes() == second.positions.tobytes()
    assert first.parent.tobytes() == second.parent.tobytes() and first.radius.tobytes() == second.radius.tobytes()
    assert first.positions.tobytes() != _grow(lobe, 4).positions.tobytes()


def test_the_tree_grows_from_the_drawn_branches_inside_the_lobe(lobe):
    skeleton = _grow(lobe)
    guide = branch_guide([TRUNK, LIMB], 0.1)
    assert np.allclose(skeleton.positions[: len(guide)], guide.positions)  # drawn branches first, as drawn
    assert np.array_equal(skeleton.parent[1: len(guide)], guide.parent[1:])
    grown = skeleton.positions[len(guide):]
    assert len(grown) > 100
    assert MeshSpace(lobe).contains(grown).mean() > 0.95  # the rest lie along the drawn branches (reach)


def test_painted_markers_outside_the_lobe_are_reached(lobe):
    painted = brush_markers(PAINT_PATH, 0.15, 4000, np.random.default_rng(1))
    assert not MeshSpace(lobe).contains(painted).any()
    plain = _grow(lobe)
    brushed = _grow(lobe, markers=painted, brush_paths=[PAINT_PATH])
    assert (plain.positions[:, 0] > 0.95).sum() == 0
    assert (brushed.positions[:, 0] > 0.95).sum() >= 5


# A crown-sized lobe (about 110 m^3: the preset's density would want over 200 000 markers) on a drawn trunk and
# two limbs, as a user draws one in the page.
CROWN_BRANCHES = [(np.array([[0, 0, 0], [0, 0, 2], [0.2, 0, 4]]), -1),
                  (np.array([[0.1, 0, 2], [1, 0, 3], [2, 0, 4]]), 0),
                  (np.array([[0.05, 0, 3], [-1, 0, 4], [-2, 0, 5]]), 0)]


@pytest.mark.parametrize("budget", [100, 1000])  # the page allows 100 and up
def test_a_low_marker_budget_still_fills_a_large_lobe(budget):
    crown = lobe_mesh([_ring(3.0, 4.0), _ring(2.5, 8.0)])
    skeleton = grow_model([crown], CROWN_BRANCHES, None, "sc_round_maple", {"max_markers": budget},
                          np.random.default_rng(0))
    assert len(skeleton.leaves) > 500  # a crown, not the bare drawn branches
    # Spread across the lobe: most of its volume lies within one marker spacing of the tree.
    inside = MeshSpace(crown).sample_markers(1e9, 2000, np.random.default_rng(1))
    spacing = np.cbrt(crown.volume / budget)
    assert (cKDTree(skeleton.positions).query(inside)[0] < spacing).mean() > 0.9


def test_buds_look_further_only_when_the_budget_spreads_the_markers():
    params = model_params("sc_round_maple", {"schedule": [[0, {"perception_radius": 4.0}], [5, {"tropism": 0.1}]]})
    preset_density = params["marker_density"] / 0.1 ** 3
    assert perception_at_budget(params, preset_density, 0.1) is params  # as dense as the preset: unchanged
    sparse = preset_density / 1000  # a cone of 4 or 5 IL holds under MIN_PERCEIVED markers there
    wider = perception_at_budget(params, sparse, 0.1)
    for phase in (wider, {**wider, **wider["schedule"][0][1]}):
        assert phase["perception_radius"] < 10 * params["perception_radius"]  # not the preset's whole spacing
        assert perceived_markers(phase, sparse, 0.1) == pytest.approx(MIN_PERCEIVED)
    assert wider["schedule"][1] == [5, {"tropism": 0.1}]
    assert wider["occupancy_radius"] == params["occupancy_radius"]  # how closely branches pack stays
    # A little sparse, the cone still holds enough: as the preset. Never wider than the preset's own spacing
    # (markers 8 times sparser: twice as far) for a preset that perceives few; at most the schema's limit.
    assert perception_at_budget(params, preset_density / 8, 0.1)["perception_radius"] == params["perception_radius"]
    short_sighted = model_params("sc_round_maple", {"perception_radius": 1.5, "occupancy_radius": 1.0})
    assert perception_at_budget(short_sighted, preset_density / 8, 0.1)["perception_radius"] == pytest.approx(3.0)
    assert perception_at_budget(params, 1e-3, 0.1)["perception_radius"] == SCHEMA["perception_radius"].high


def test_branches_drawn_either_way_make_the_same_guide():
    forward = branch_guide([TRUNK, LIMB], 0.1)
    backward = branch_guide([(TRUNK[0][::-1], -1), (LIMB[0][::-1], 0)], 0.1)
    assert np.allclose(forward.positions, backward.positions) and np.array_equal(forward.parent, backward.parent)
    assert np.allclose(forward.positions[0], 0.0) and forward.order.max() == 1


def test_without_branches_a_trunk_runs_from_the_origin_into_the_lowest_lobe(lobe):
    skeleton = grow_model([lobe], [], None, "sc_round_maple", FAST, np.random.default_rng(0))
    assert np.allclose(skeleton.positions[0], 0.0) and len(skeleton) > 100


def test_the_growth_space_reaches_round_markers_and_branches(lobe):
    guide = branch_guide([TRUNK], 0.1)
    space = model_space([lobe], guide, np.array([[2.0, 0.0, 2.0]]), 0.1)
    assert space.contains(np.array([[0.0, 0.0, 1.5], [2.1, 0.0, 2.0], [0.05, 0.0, 0.5]])).all()
    assert not space.contains(np.array([[2.3, 0.0, 2.0], [0.5, 0.0, 0.5]])).any()


def test_preset_overrides_are_validated():
    assert model_params("sc_spruce", {"iterations": 7})["iterations"] == 7
    with pytest.raises(ParameterError, match="iterations"):
        model_params("sc_spruce", {"iterations": -1})


def test_brush_markers_fill_balls_along_the_path():
    markers = brush_markers(PAINT_PATH, 0.2, 5000, np.random.default_rng(2))
    length = np.linalg.norm(PAINT_PATH[1] - PAINT_PATH[0])
    assert len(markers) == round(5000 * (np.pi * 0.04 * length + 4 / 3 * np.pi * 0.008))
    along = np.clip((markers - PAINT_PATH[0]) @ (PAINT_PATH[1] - PAINT_PATH[0]) / length ** 2, 0, 1)
    nearest = PAINT_PATH[0] + along[:, None] * (PAINT_PATH[1] - PAINT_PATH[0])
    assert np.linalg.norm(markers - nearest, axis=1).max() <= 0.2
    assert np.array_equal(markers, brush_markers(PAINT_PATH, 0.2, 5000, np.random.default_rng(2)))
    with pytest.raises(BrushError, match="radius"):
        brush_markers(PAINT_PATH, 0.0, 5000, np.random.default_rng(2))
    with pytest.raises(BrushError, match="at most"):
        brush_markers(PAINT_PATH, 5.0, 5000, np.random.default_rng(2))


@pytest.mark.parametrize("lobes, branches, markers, preset, message", [
    ("lobe", [TRUNK], None, "no_such_tree", "unknown; allowed: .*sc_round_maple"),
    ("lobe", [TRUNK], None, "black_oak", "colonization preset"),
    (None, [TRUNK], None, "sc_round_maple", "empty"),
    ("lobe", [TRUNK, TRUNK], None, "sc_round_maple", "2 trunks"),
    ("lobe", [TRUNK, (LIMB[0], 2), (LIMB[0], 1)], None, "sc_round_maple", "loop"),
    ("lobe", [TRUNK, (LIMB[0], 7)], None, "sc_round_maple", "parent 7"),
    ("lobe", [(np.zeros((1, 3)), -1)], None, "sc_round_maple", "K >= 2"),
    ("lobe", [TRUNK], np.array([[np.nan, 0, 0]]), "sc_round_maple", "finite points"),
    ("lobe", [TRUNK], np.zeros((4, 2)), "sc_round_maple", r"shape \(M, 3\)"),
])
def test_models_that_cannot_grow_are_refused(lobe, lobes, branches, markers, preset, message):
    with pytest.raises(ModelError, match=message):
        grow_model([lobe] if lobes else [], branches, markers, preset, None, np.random.default_rng(0))
    assert issubclass(ModelError, ValueError)
