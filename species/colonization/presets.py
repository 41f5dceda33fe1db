"""Self-organizing growth presets: 24 species templates for `species.colonization` (thesis 000 trains on 20).

Each fixes what identifies the habit (crown shape, allocation, apical control, tropism) and samples the rest:
size in metres, crown proportions in internode lengths, lambda or kappa, angles. Names start with "sc_".
"""
from __future__ import annotations

from typing import Any

from ..presets import Choice, IntRange, Jitter, Preset

__all__ = ["PRESETS"]

# Shared by every template; sized so a tree grows well within the thesis's growth time per tree, on one core
# (`python -m benchmarks.bench_colonization` times the presets).
_BASE: dict[str, Any] = {"marker_density": 2.0, "max_markers": 20000, "iterations": 40}


def _uniform(low: float, high: float) -> Jitter:
    """U(low, high) for 0 < low <= high, as a Jitter (presets.Uniform fails on scalars with numpy 2)."""
    centre = (low + high) / 2
    return Jitter(centre, rel=(high - low) / (high + low), low=low, high=high)


def _make(name: str, description: str, fixed: dict, ranges: dict, *,
          bark=(0.33, 0.25, 0.18), leaf=(0.25, 0.45, 0.15)) -> Preset:
    """A template: shared base + `fixed`, with the common size draws unless `ranges` overrides them."""
    common = {
        "crown_radius": Jitter(fixed.pop("crown_radius", 12.0), rel=0.15, low=1.0),
        "crown_height": Jitter(fixed.pop("crown_height", 20.0), rel=0.15, low=1.0),
        "crown_base": Jitter(fixed.pop("crown_base", 6.0), rel=0.2, low=0.0),
        "branch_angle": Jitter(fixed.pop("branch_angle", 45.0), rel=0.0, add=8.0, low=0.0, high=179.0),
        "tropism": Jitter(fixed.pop("tropism", 0.15), rel=0.0, add=0.08, low=-3.0, high=3.0),
    }
    body = {**_BASE, **fixed, "bark_color": list(bark), "leaf_color": list(leaf)}
    return Preset(name=name, generator="colonization", description=description, fixed=body,
                  ranges={**common, **ranges})


PRESETS: list[Preset] = [
    _make("sc_excurrent_leader", "tall single leader, strong apical control (priority model, small kappa)",
          {"crown_shape": "teardrop", "crown_radius": 9.0, "crown_height": 32.0, "crown_base": 8.0,
           "allocation": "priority", "tropism": 0.8, "branch_angle": 55.0},
          {"height": _uniform(14.0, 22.0), "kappa": _uniform(0.22, 0.3)}),
    _make("sc_broad_oak", "broad spreading crown, laterals favoured, wide branch angles",
          {"crown_shape": "ellipsoid", "crown_radius": 19.0, "crown_height": 18.0, "crown_base": 6.0,
           "tropism": 0.05, "branch_angle": 55.0},
          {"height": _uniform(10.0, 16.0), "lambda": _uniform(0.46, 0.52)}),
    _make("sc_round_maple", "round crown, balanced Borchert-Honda allocation",
          {"crown_shape": "ellipsoid", "crown_radius": 13.0, "crown_height": 20.0, "crown_base": 6.0},
          {"height": _uniform(9.0, 15.0), "lambda": _uniform(0.52, 0.6)}),
    _make("sc_vase_elm", "vase habit: upright forks spreading toward a wide top",
          {"crown_shape": "vase", "crown_radius": 16.0, "crown_height": 22.0, "crown_base": 5.0,
           "tropism": 0.35, "branch_angle": 32.0},
          {"height": _uniform(12.0, 20.0), "lambda": _uniform(0.45, 0.5)}),
    _make("sc_dome_shrub", "low dome shrub on several stems",
          {"crown_shape": "dome", "crown_radius": 10.0, "crown_height": 9.0, "crown_base": 0.0,
           "tropism": 0.1},
          {"height": _uniform(1.0, 2.5), "stems": IntRange(3, 5), "lambda": _uniform(0.45, 0.55)}),
    _make("sc_multistem_shrub", "upright multi-stem shrub, laterals favoured",
          {"crown_shape": "ellipsoid", "crown_radius": 8.0, "crown_height": 14.0, "crown_base": 0.0,
           "stem_spread": 18.0, "tropism": 0.3},
          {"height": _uniform(1.5, 4.0), "stems": IntRange(4, 6), "lambda": _uniform(0.42, 0.5)}),
    _make("sc_weeping_willow", "weeping: upright when young, then drooping shoots (tropism changes with age)",
          {"crown_shape": "ellipsoid", "crown_radius": 16.0, "crown_height": 28.0, "crown_base": 2.0,
           "tropism": -0.9, "optimal_weight": 0.7, "branch_angle": 40.0,
           "schedule": [[0, {"tropism": 0.6, "optimal_weight": 1.0}], [6, {}]]},
          {"height": _uniform(8.0, 14.0), "lambda": _uniform(0.5, 0.56)},
          leaf=(0.35, 0.5, 0.18)),
    _make("sc_columnar_poplar", "columnar: narrow cylinder, steep branches",
          {"crown_shape": "cylinder", "crown_radius": 4.5, "crown_height": 36.0, "crown_base": 3.0,
           "tropism": 0.6, "branch_angle": 22.0},
          {"height": _uniform(15.0, 25.0), "lambda": _uniform(0.55, 0.62)}),
    _make("sc_cypress_column", "narrow flame-shaped evergreen column",
          {"crown_shape": "teardrop", "crown_radius": 5.5, "crown_height": 30.0, "crown_base": 1.0,
           "allocation": "priority", "tropism": 0.5, "branch_angle": 30.0},
          {"height": _uniform(8.0, 16.0), "kappa": _uniform(0.35, 0.5)}, leaf=(0.12, 0.28, 0.12)),
    _make("sc_sympodial_lilac", "sympodial shrub: every apex aborts after it grows, laterals take over",
          {"crown_shape": "ellipsoid", "crown_radius": 9.0, "crown_height": 14.0, "crown_base": 0.0,
           "apical_abort": 1.0, "stems": 2, "tropism": 0.3},
          {"height": _uniform(2.0, 4.5), "lambda": _uniform(0.48, 0.55)}),
    _make("sc_sympodial_candelabra", "sympodial tree: forking candelabra crown from aborting apices",
          {"crown_shape": "umbrella", "crown_radius": 14.0, "crown_height": 16.0, "crown_base": 8.0,
           "apical_abort": 0.8, "tropism": 0.4, "branch_angle": 35.0},
          {"height": _uniform(6.0, 11.0), "lambda": _uniform(0.48, 0.55)}),
    _make("sc_spruce", "conifer-like: cone crown, dominant leader, near-horizontal laterals",
          {"crown_shape": "cone", "crown_radius": 10.0, "crown_height": 36.0, "crown_base": 2.0,
           "allocation": "priority", "tropism": 0.6, "branch_angle": 80.0, "perception_angle": 120.0,
           "bud_lifetime": 5,
           "schedule": [[0, {"kappa": 0.15}], [8, {}]]},
          {"height": _uniform(12.0, 25.0), "kappa": _uniform(0.25, 0.35)}, leaf=(0.1, 0.25, 0.12)),
    _make("sc_fir", "conifer-like: narrow cone, very strong apical control",
          {"crown_shape": "cone", "crown_radius": 7.5, "crown_height": 34.0, "crown_base": 2.0,
           "allocation": "priority", "tropism": 0.7, "branch_angle": 70.0, "bud_lifetime": 5},
          {"height": _uniform(10.0, 22.0), "kappa": _uniform(0.2, 0.3)}, leaf=(0.1, 0.22, 0.12)),
    _make("sc_umbrella_pine", "umbrella pine: tall bare bole under a wide flat crown",
          {"crown_shape": "umbrella", "crown_radius": 17.0, "crown_height": 10.0, "crown_base": 16.0,
           "tropism": 0.25, "branch_angle": 35.0},
          {"height": _uniform(10.0, 18.0), "lambda": _uniform(0.46, 0.52)}, leaf=(0.12, 0.3, 0.12)),
    _make("sc_flat_acacia", "savanna acacia: flat, boxy-topped wide crown on a short trunk",
          {"crown_shape": "superquadric", "crown_exponent": 3.0, "crown_radius": 18.0, "crown_height": 10.0,
           "crown_base": 12.0, "tropism": 0.05, "branch_angle": 50.0},
          {"height": _uniform(5.0, 9.0), "lambda": _uniform(0.44, 0.5)}),
    _make("sc_birch_oval", "narrow oval crown with hanging twigs",
          {"crown_shape": "teardrop", "crown_radius": 8.0, "crown_height": 26.0, "crown_base": 6.0,
           "tropism": -0.1, "branch_angle": 40.0},
          {"height": _uniform(12.0, 20.0), "lambda": _uniform(0.56, 0.64)}, bark=(0.75, 0.73, 0.7)),
    _make("sc_dense_beech", "dense round crown, graded light (Q = n / (n + 3))",
          {"crown_shape": "ellipsoid", "crown_radius": 15.0, "crown_height": 22.0, "crown_base": 4.0,
           "light_model": "graded", "alpha": 3.0},
          {"height": _uniform(14.0, 24.0), "lambda": _uniform(0.5, 0.58)}, bark=(0.5, 0.5, 0.48)),
    _make("sc_open_fruit_tree", "pruned-looking orchard tree: low open vase crown",
          {"crown_shape": "vase", "crown_radius": 12.0, "crown_height": 11.0, "crown_base": 4.0,
           "tropism": 0.2, "branch_angle": 48.0},
          {"height": _uniform(3.0, 6.0), "lambda": _uniform(0.44, 0.5)}),
    _make("sc_lobed_cloud", "irregular crown of random ellipsoid lobes",
          {"crown_shape": "lobes", "crown_radius": 16.0, "crown_height": 24.0, "crown_base": 6.0},
          {"height": _uniform(8.0, 16.0), "crown_lobes": IntRange(3, 5), "lambda": _uniform(0.5, 0.58)}),
    _make("sc_superquadric_lobes", "crown of random boxy superquadric lobes (cloud-pruned look)",
          {"crown_shape": "lobes", "crown_radius": 14.0, "crown_height": 20.0, "crown_base": 5.0},
          {"height": _uniform(4.0, 9.0), "crown_lobes": IntRange(2, 4), "crown_exponent": _uniform(3.0, 5.0),
           "lambda": _uniform(0.5, 0.56)}),
    _make("sc_shadow_oak", "broad tree grown by shadow propagation (light as the resource)",
          {"crown_shape": "ellipsoid", "crown_radius": 15.0, "crown_height": 18.0, "crown_base": 5.0,
           "resource": "shadow", "shadow_exposure": 4.0, "branch_angle": 50.0},
          {"height": _uniform(9.0, 15.0), "lambda": _uniform(0.48, 0.56)}),
    _make("sc_shadow_conifer", "conifer-like cone grown by shadow propagation",
          {"crown_shape": "cone", "crown_radius": 8.0, "crown_height": 30.0, "crown_base": 2.0,
           "resource": "shadow", "shadow_exposure": 4.0, "tropism": 0.35, "branch_angle": 75.0,
           "bud_lifetime": 6},
          {"height": _uniform(10.0, 20.0), "lambda": _uniform(0.6, 0.68)}, leaf=(0.1, 0.25, 0.12)),
    _make("sc_young_sapling", "young sapling: small crown, few steps, thin stem",
          {"crown_shape": "teardrop", "crown_radius": 5.0, "crown_height": 12.0, "crown_base": 4.0,
           "iterations": 12, "tropism": 0.4},
          {"height": _uniform(1.0, 2.5), "lambda": _uniform(0.55, 0.65)}),
    _make("sc_self_pruning_forest_tree", "forest tree that sheds its shaded lower branches (Palubicki shedding)",
          {"crown_shape": "teardrop", "crown_radius": 11.0, "crown_height": 26.0, "crown_base": 10.0,
           "shed_ratio": 0.1, "shed_patience": 3, "tropism": 0.3},
          {"height": _uniform(16.0, 28.0), "lambda": _uniform(0.55, 0.62),
           "light_model": Choice(("binary", "graded"))}),
]
