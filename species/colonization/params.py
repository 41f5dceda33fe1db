"""The parameter schema of self-organizing growth: keys, types, ranges, defaults, and the age schedule.

`validate(params) -> dict` fills defaults and raises ParameterError naming the key for anything else.
Lengths are in internode lengths (IL; 1 IL = 0.1 m at reference scale), angles in degrees.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import ParameterError
from .growth_space import PROFILE_SHAPES

__all__ = ["Field", "SCHEMA", "SCHEDULABLE", "validate", "at_iteration", "CROWN_SHAPES"]

CROWN_SHAPES = PROFILE_SHAPES + ("lobes", "superquadric")


@dataclass(frozen=True)
class Field:
    """One key: kind in {"float", "int", "bool", "choice"}, its default, and its closed range or options."""

    kind: str
    default: Any
    low: float | None = None
    high: float | None = None
    options: tuple = ()
    doc: str = ""

    def allowed(self) -> str:
        if self.kind == "choice":
            return f"one of {list(self.options)}"
        if self.kind == "bool":
            return "true or false"
        noun = "an integer" if self.kind == "int" else "a number"
        return f"{noun} in [{self.low}, {self.high}]"

    def check(self, key: str, value: Any) -> Any:
        if self.kind == "choice":
            if value not in self.options:
                raise ParameterError(key, value, self.allowed())
            return value
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise ParameterError(key, value, self.allowed())
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(key, value, self.allowed())
        if self.kind == "int":
            if int(value) != value:
                raise ParameterError(key, value, self.allowed())
            value = int(value)
        else:
            value = float(value)
        if not math.isfinite(value) or not self.low <= value <= self.high:
            raise ParameterError(key, value, self.allowed())
        return value


SCHEMA: dict[str, Field] = {
    # size and stopping
    "height": Field("float", 0.0, 0.0, 200.0, doc="metres of the grown tree; 0 keeps the reference scale"),
    "iterations": Field("int", 30, 1, 200, doc="growth steps at most; stops after 2 steps without growth"),
    # growth space (the crown envelope, IL) and markers
    "crown_shape": Field("choice", "ellipsoid", options=CROWN_SHAPES),
    "crown_radius": Field("float", 12.0, 1.0, 200.0, doc="IL, horizontal half-width"),
    "crown_height": Field("float", 20.0, 1.0, 400.0, doc="IL, vertical extent"),
    "crown_base": Field("float", 8.0, 0.0, 400.0, doc="IL above the ground where the crown starts"),
    "crown_exponent": Field("float", 2.0, 0.5, 10.0, doc="superquadric exponent (lobes, superquadric)"),
    "crown_lobes": Field("int", 3, 1, 8),
    "marker_density": Field("float", 8.0, 0.01, 64.0, doc="markers per IL^3"),
    "max_markers": Field("int", 60000, 100, 500000),
    # space colonization (digest 1.2)
    "occupancy_radius": Field("float", 2.0, 0.1, 20.0, doc="IL, rho"),
    "perception_radius": Field("float", 5.0, 0.2, 40.0, doc="IL, r"),
    "perception_angle": Field("float", 90.0, 1.0, 360.0, doc="degrees, full apex angle theta"),
    "resource": Field("choice", "space", options=("space", "shadow")),
    "light_model": Field("choice", "binary", options=("binary", "graded")),
    # shadow propagation (digest 1.3)
    "shadow_a": Field("float", 1.0, 0.01, 10.0),
    "shadow_b": Field("float", 2.0, 1.01, 10.0),
    "shadow_depth": Field("int", 6, 1, 20),
    "shadow_exposure": Field("float", 3.0, 0.01, 20.0, doc="C, full exposure (Q is divided by C)"),
    "shadow_direction": Field("choice", "least_shaded", options=("least_shaded", "gradient"),
                              doc="V_opt toward the least shaded neighbour voxel, or along -grad(s)"),
    # allocation (digest 1.5, 1.6)
    "allocation": Field("choice", "borchert_honda", options=("borchert_honda", "priority")),
    "alpha": Field("float", 2.0, 0.01, 20.0, doc="root pool = alpha * Q_base"),
    "lambda": Field("float", 0.55, 0.0, 1.0, doc="main-axis share in Borchert-Honda"),
    "kappa": Field("float", 0.5, 0.01, 1.0, doc="priority ramp length; smaller = stronger leader"),
    "max_internodes_per_step": Field("int", 3, 1, 10),
    # direction (digest 1.4) and branching
    "default_weight": Field("float", 0.4, 0.0, 10.0, doc="a, weight of the bud's own direction"),
    "optimal_weight": Field("float", 1.0, 0.0, 10.0, doc="b, weight of the optimal (free-space) direction"),
    "tropism": Field("float", 0.15, -3.0, 3.0, doc="g, weight of straight up; negative droops"),
    "attraction_weight": Field("float", 0.5, 0.0, 10.0, doc="alpha of eq. 3.6 (direction field)"),
    "branch_angle": Field("float", 45.0, 0.0, 179.0, doc="degrees between a lateral bud and its axis"),
    "phyllotaxis": Field("float", 137.5, 0.0, 360.0, doc="degrees of divergence between successive buds"),
    # bud fate and shedding
    "bud_lifetime": Field("int", 3, 1, 1000, doc="steps a bud may stay without growing before it dies"),
    "apical_abort": Field("float", 0.0, 0.0, 1.0, doc="chance an apical bud dies after it grows (sympodial)"),
    "shed_ratio": Field("float", 0.0, 0.0, 1.0,
                        doc="shed a branch whose Q per internode stays below this times the tree's; 0 = off"),
    "shed_patience": Field("int", 2, 1, 100, doc="steps the ratio must stay low before the branch falls"),
    # stems from the base
    "stems": Field("int", 1, 1, 8),
    "stem_spread": Field("float", 25.0, 0.0, 80.0, doc="degrees from vertical of extra stems"),
    # radii and leaves (digest 1.7)
    "pipe_exponent": Field("float", 2.5, 2.0, 3.0, doc="n of d^n = sum of children's d^n"),
    "tip_diameter": Field("float", 0.1, 0.001, 5.0, doc="IL"),
    "leaf_age": Field("int", 3, 0, 100, doc="leaves on each axis's internodes of its last steps; 0 = none"),
    "leaves_per_node": Field("int", 2, 0, 8),
    "leaf_size": Field("float", 0.6, 0.01, 20.0, doc="IL, card width"),
    "leaf_aspect": Field("float", 1.0, 0.1, 10.0, doc="card length / width"),
    "leaf_min_order": Field("int", 1, 0, 20),
}

SCHEDULABLE = frozenset({
    "occupancy_radius", "perception_radius", "perception_angle", "alpha", "lambda", "kappa",
    "max_internodes_per_step", "default_weight", "optimal_weight", "tropism", "attraction_weight",
    "branch_angle", "phyllotaxis", "bud_lifetime", "apical_abort", "shed_ratio",
})

_META = ("generator", "species", "seed", "schedule")
# Keys other stages read (the mesher: species.mesh.build_mesh); passed through untouched.
_PASSED_THROUGH = ("bark_color", "leaf_color", "mesh_radial_segments", "mesh_min_segments", "name")


def _check_schedule(schedule: Any) -> list:
    allowed = "a list of [iteration, {key: value}] entries with increasing iterations >= 0 and keys among " \
              f"{sorted(SCHEDULABLE)}"
    if not isinstance(schedule, (list, tuple)):
        raise ParameterError("schedule", schedule, allowed)
    entries, last = [], -1
    for entry in schedule:
        if (not isinstance(entry, (list, tuple)) or len(entry) != 2 or isinstance(entry[0], bool)
                or not isinstance(entry[0], int) or entry[0] <= last or not isinstance(entry[1], dict)):
            raise ParameterError("schedule", entry, allowed)
        overrides = {}
        for key, value in entry[1].items():
            if key not in SCHEDULABLE:
                raise ParameterError(f"schedule[{entry[0]}].{key}", value, f"a key among {sorted(SCHEDULABLE)}")
            overrides[key] = SCHEMA[key].check(f"schedule[{entry[0]}].{key}", value)
        entries.append([int(entry[0]), overrides])
        last = entry[0]
    return entries


def validate(params: dict) -> dict:
    """A complete copy of `params` with defaults filled in; raises ParameterError on any bad key or value."""
    if not isinstance(params, dict):
        raise ParameterError("params", type(params).__name__, "a JSON object (dict) of parameters")
    if params.get("generator", "colonization") != "colonization":
        raise ParameterError("generator", params.get("generator"), "'colonization'")
    for key in params:
        if key not in SCHEMA and key not in _META and key not in _PASSED_THROUGH:
            known = sorted(list(SCHEMA) + list(_META) + list(_PASSED_THROUGH))
            raise ParameterError(key, params[key], f"a known key: {', '.join(known)}")
    out = {key: field.check(key, params[key]) if key in params else field.default for key, field in SCHEMA.items()}
    out["generator"] = "colonization"
    out["species"] = params.get("species", "")
    if not isinstance(out["species"], str):
        raise ParameterError("species", out["species"], "a string")
    out["schedule"] = _check_schedule(params.get("schedule", []))
    seed = params.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ParameterError("seed", seed, "a non-negative integer")
    out["seed"] = seed
    out.update({key: params[key] for key in _PASSED_THROUGH if key in params})
    if out["perception_radius"] <= out["occupancy_radius"]:
        raise ParameterError("perception_radius", out["perception_radius"],
                             f"a radius larger than occupancy_radius = {out['occupancy_radius']}")
    return out


def at_iteration(params: dict, iteration: int) -> dict:
    """The parameters in force at `iteration`.

    The schedule is a list of phases: entry [start, overrides] holds from `start` until the next entry's
    start, and means the base values with its overrides; an empty dict returns to the base values.
    """
    current = dict(params)
    phase = {}
    for start, overrides in params["schedule"]:
        if start <= iteration:
            phase = overrides
    current.update(phase)
    return current
