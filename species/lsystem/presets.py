"""Classic L-system plants (ABOP and thesis 003) as species presets with sampled angles, sizes and depths.

Out: `PRESETS`, a list of `species.presets.Preset` with generator "lsystem"; each tree stays under ~20k nodes.
"""
from __future__ import annotations

from ..presets import Choice, IntRange, Jitter, Preset

__all__ = ["PRESETS"]


class _Constants:
    """Draws the `constants` dict, each entry from its Jitter; `typical` gives every centre (for `fixed`)."""

    def __init__(self, **ranges: Jitter):
        self.ranges = ranges

    def __call__(self, rng, params) -> dict:
        return {name: self.ranges[name].draw(rng) for name in sorted(self.ranges)}

    @property
    def typical(self) -> dict:
        return {name: float(spec.base) for name, spec in self.ranges.items()}


def _sampled(fixed: dict, ranges: dict) -> tuple[dict, dict]:
    """Put each callable range's typical value into `fixed` too, so `Preset.base_params` stays growable."""
    fixed = dict(fixed)
    for key, spec in ranges.items():
        if isinstance(spec, _Constants):
            fixed[key] = spec.typical
        elif isinstance(spec, _Droop):
            fixed[key] = [0.0, 0.0, -(spec.low + spec.high) / 2]
    return fixed, ranges


def _uniform(low: float, high: float) -> Jitter:
    """U(low, high) as a Jitter about the centre, so `Preset.base_params` knows the typical value."""
    centre = (low + high) / 2
    return Jitter(centre, rel=(high - low) / (high + low) if centre else 0.0)


class _Droop:
    """Draws a downward tropism vector of length U(low, high)."""

    def __init__(self, low: float, high: float):
        self.low, self.high = low, high

    def __call__(self, rng, params) -> list[float]:
        return [0.0, 0.0, -float(rng.uniform(self.low, self.high))]


def _preset(name: str, description: str, fixed: dict, ranges: dict) -> Preset:
    fixed, ranges = _sampled(fixed, ranges)
    return Preset(name=name, generator="lsystem", description=description, fixed=fixed, ranges=ranges)


PRESETS: list[Preset] = [
    _preset(
        name="lsystem_abop_tree",
        description="ABOP fig. 2.8 ternary tree: three branches per node, internodes lengthening with age, droop",
        fixed={"axiom": "F(200)/(45)A",
               "rules": ["A -> F(50)[&(a)F(50)A]/(d1)[&(a)F(50)A]/(d2)[&(a)F(50)A]", "F(l) -> F(l*lr)"],
               "radii": "pipe", "tip_radius": 0.005, "leaves_per_tip": 3},
        ranges={"constants": _Constants(a=Jitter(18.95, 0.25), lr=Jitter(1.109, 0.02), d1=Jitter(94.74, 0.1),
                                        d2=Jitter(132.63, 0.1)),
                "iterations": IntRange(6, 7), "step": _uniform(0.005, 0.008), "tropism": _Droop(0.1, 0.3),
                "angle_jitter": _uniform(0.0, 6.0), "leaf_size": _uniform(0.07, 0.12)},
    ),
    _preset(
        name="lsystem_bush",
        description="ABOP fig. 1.25 bush: three-way apices, spiralling internodes, leaves along every shoot",
        fixed={"axiom": "A", "rules": ["A -> [&FL!A]/////[&FL!A]///////[&FL!A]", "F -> S/////F", "S -> FL"],
               "radii": "turtle", "leaves_per_tip": 1},
        ranges={"iterations": IntRange(6, 7), "angle": Jitter(22.5, 0.2), "step": _uniform(0.1, 0.16),
                "width": _uniform(0.05, 0.08), "width_ratio": _uniform(0.7, 0.8), "angle_jitter": _uniform(0.0, 8.0),
                "tropism": _Droop(0.0, 0.08), "leaf_size": _uniform(0.06, 0.1)},
    ),
    _preset(
        name="lsystem_fractal_plant",
        description="ABOP fig. 1.24f fractal plant, rolled at every apex to fill 3D: a weedy, leaning shrub",
        fixed={"axiom": "X", "rules": ["X -> F/(r)+[[X]-X]-F[-X]+X", "F -> FF"], "radii": "pipe",
               "tip_radius": 0.002, "leaves_per_tip": 2},
        ranges={"constants": _Constants(r=_uniform(60.0, 140.0)), "iterations": IntRange(4, 5),
                "angle": Jitter(25.0, 0.15), "step": _uniform(0.04, 0.06), "angle_jitter": _uniform(0.0, 6.0),
                "leaf_size": _uniform(0.04, 0.07)},
    ),
    _preset(
        name="lsystem_monopodial",
        description="ABOP fig. 2.6 monopodial tree: one leader, lateral axes branching in alternate planes",
        fixed={"axiom": "A(1)",
               "rules": ["A(l) -> !(wr)F(l)[&(a0)B(l*r2)]/(d)A(l*r1)",
                         "B(l) -> !(wr)F(l)[-(a2)C(l*r2)]C(l*r1)",
                         "C(l) -> !(wr)F(l)[+(a2)B(l*r2)]B(l*r1)"],
               "radii": "turtle", "width": 0.35, "leaves_per_tip": 3},
        ranges={"constants": _Constants(r1=Jitter(0.9, 0.04), r2=Jitter(0.6, 0.15), a0=Jitter(45.0, 0.2),
                                        a2=Jitter(45.0, 0.2), d=Jitter(137.5, 0.05), wr=Jitter(0.707, 0.05)),
                "iterations": IntRange(9, 11), "step": _uniform(0.8, 1.2), "angle_jitter": _uniform(0.0, 5.0),
                "tropism": _Droop(0.0, 0.04), "leaf_size": _uniform(0.1, 0.16)},
    ),
    _preset(
        name="lsystem_sympodial",
        description="ABOP fig. 2.7 sympodial tree: every apex forks into two unequal daughters",
        fixed={"axiom": "A(1)",
               "rules": ["A(l) -> !(wr)F(l)[&(a1)B(l*r1)]/(180)[&(a2)B(l*r2)]",
                         "B(l) -> !(wr)F(l)[+(a1)/(90)B(l*r1)][-(a2)/(90)B(l*r2)]"],
               "radii": "turtle", "width": 0.3, "leaves_per_tip": 2},
        ranges={"constants": _Constants(r1=Jitter(0.9, 0.04), r2=Jitter(0.7, 0.1), a1=Jitter(10.0, 0.3),
                                        a2=Jitter(60.0, 0.15), wr=Jitter(0.707, 0.05)),
                "iterations": IntRange(9, 11), "step": _uniform(1.5, 2.2), "angle_jitter": _uniform(0.0, 5.0),
                "tropism": _Droop(0.0, 0.06), "leaf_size": _uniform(0.1, 0.16)},
    ),
    _preset(
        name="lsystem_stochastic_shrub",
        description="ABOP fig. 1.27 stochastic plant in 3D, with alternate (cherry-like) leaf twigs at the tips",
        fixed={"axiom": "F",
               "rules": ["F -> F[+F]/(r)F[-F]F : 0.33", "F -> F[+F]/(r)F : 0.33", "F -> F[-F]/(r)F : 0.34"],
               "radii": "pipe", "tip_radius": 0.002, "twigs": "alternate"},
        ranges={"constants": _Constants(r=_uniform(70.0, 120.0)), "iterations": IntRange(4, 5),
                "angle": Jitter(25.7, 0.15), "step": _uniform(0.035, 0.055), "angle_jitter": _uniform(0.0, 6.0),
                "twig_angle": _uniform(35.0, 55.0), "leaf_size": _uniform(0.04, 0.06)},
    ),
    _preset(
        name="lsystem_dichotomous",
        description="Thesis 003 example X -> F[-X][+X] in 3D (forks turn 90 degrees each level), opposite leaf twigs",
        fixed={"axiom": "X(1)", "rules": ["X(l) -> F(l)/(90)[-X(l*k)][+X(l*k)]"], "radii": "pipe",
               "tip_radius": 0.004, "twigs": "opposite"},
        ranges={"constants": _Constants(k=_uniform(0.72, 0.85)), "iterations": IntRange(7, 9),
                "angle": Choice((30.0, 25.0, 35.0)), "step": _uniform(1.2, 1.8), "angle_jitter": _uniform(2.0, 8.0),
                "tropism": _Droop(0.0, 0.05), "twig_step": _uniform(0.04, 0.06), "leaf_size": _uniform(0.05, 0.08)},
    ),
]
