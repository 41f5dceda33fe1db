"""Classic L-system plants (ABOP and thesis 003) as species presets with sampled angles, sizes and depths.

Out: `PRESETS`, a list of `species.presets.Preset` with generator "lsystem"; each tree stays under ~20k nodes.
"""
from __future__ import annotations

from .presets import Choice, IntRange, Jitter, Preset

__all__ = ["PRESETS"]


def _constants(**ranges):
    """A range spec drawing a `constants` dict: each entry a Jitter (or a fixed number)."""
    def draw(rng, params):
        return {name: (spec.draw(rng) if hasattr(spec, "draw") else float(spec)) for name, spec in sorted(ranges.items())}
    return draw


class Uniform:
    """A float drawn from U(low, high). (presets.Uniform.draw fails on scalar ranges: numpy returns a float.)"""

    def __init__(self, low: float, high: float):
        self.low, self.high = low, high

    def draw(self, rng) -> float:
        return float(rng.uniform(self.low, self.high))


def _droop(low: float, high: float):
    """A range spec for a downward tropism vector of length U(low, high)."""
    def draw(rng, params):
        return [0.0, 0.0, -float(rng.uniform(low, high))]
    return draw


PRESETS: list[Preset] = [
    Preset(
        name="lsystem_abop_tree",
        generator="lsystem",
        description="ABOP fig. 2.8 ternary tree: three branches per node, internodes lengthening with age, droop",
        fixed={"axiom": "F(200)/(45)A",
               "rules": ["A -> F(50)[&(a)F(50)A]/(d1)[&(a)F(50)A]/(d2)[&(a)F(50)A]", "F(l) -> F(l*lr)"],
               "radii": "pipe", "tip_radius": 0.005, "leaves_per_tip": 3},
        ranges={"constants": _constants(a=Jitter(18.95, 0.25), lr=Jitter(1.109, 0.02), d1=Jitter(94.74, 0.1),
                                        d2=Jitter(132.63, 0.1)),
                "iterations": IntRange(6, 7), "step": Uniform(0.005, 0.008), "tropism": _droop(0.1, 0.3),
                "angle_jitter": Uniform(0.0, 6.0), "leaf_size": Uniform(0.07, 0.12)},
    ),
    Preset(
        name="lsystem_bush",
        generator="lsystem",
        description="ABOP fig. 1.25 bush: three-way apices, spiralling internodes, leaves along every shoot",
        fixed={"axiom": "A", "rules": ["A -> [&FL!A]/////[&FL!A]///////[&FL!A]", "F -> S/////F", "S -> FL"],
               "radii": "turtle", "leaves_per_tip": 1},
        ranges={"iterations": IntRange(6, 7), "angle": Jitter(22.5, 0.2), "step": Uniform(0.1, 0.16),
                "width": Uniform(0.05, 0.08), "width_ratio": Uniform(0.7, 0.8), "angle_jitter": Uniform(0.0, 8.0),
                "tropism": _droop(0.0, 0.08), "leaf_size": Uniform(0.06, 0.1)},
    ),
    Preset(
        name="lsystem_fractal_plant",
        generator="lsystem",
        description="ABOP fig. 1.24f fractal plant, rolled at every apex to fill 3D: a weedy, leaning shrub",
        fixed={"axiom": "X", "rules": ["X -> F/(r)+[[X]-X]-F[-X]+X", "F -> FF"], "radii": "pipe",
               "tip_radius": 0.002, "leaves_per_tip": 2},
        ranges={"constants": _constants(r=Uniform(60.0, 140.0)), "iterations": IntRange(4, 5),
                "angle": Jitter(25.0, 0.15), "step": Uniform(0.04, 0.06), "angle_jitter": Uniform(0.0, 6.0),
                "leaf_size": Uniform(0.04, 0.07)},
    ),
    Preset(
        name="lsystem_monopodial",
        generator="lsystem",
        description="ABOP fig. 2.6 monopodial tree: one leader, lateral axes branching in alternate planes",
        fixed={"axiom": "A(1)",
               "rules": ["A(l) -> !(wr)F(l)[&(a0)B(l*r2)]/(d)A(l*r1)",
                         "B(l) -> !(wr)F(l)[-(a2)C(l*r2)]C(l*r1)",
                         "C(l) -> !(wr)F(l)[+(a2)B(l*r2)]B(l*r1)"],
               "radii": "turtle", "width": 0.35, "leaves_per_tip": 3},
        ranges={"constants": _constants(r1=Jitter(0.9, 0.04), r2=Jitter(0.6, 0.15), a0=Jitter(45.0, 0.2),
                                        a2=Jitter(45.0, 0.2), d=Jitter(137.5, 0.05), wr=Jitter(0.707, 0.05)),
                "iterations": IntRange(9, 11), "step": Uniform(0.8, 1.2), "angle_jitter": Uniform(0.0, 5.0),
                "tropism": _droop(0.0, 0.1), "leaf_size": Uniform(0.1, 0.16)},
    ),
    Preset(
        name="lsystem_sympodial",
        generator="lsystem",
        description="ABOP fig. 2.7 sympodial tree: every apex forks into two unequal daughters",
        fixed={"axiom": "A(1)",
               "rules": ["A(l) -> !(wr)F(l)[&(a1)B(l*r1)]/(180)[&(a2)B(l*r2)]",
                         "B(l) -> !(wr)F(l)[+(a1)/(90)B(l*r1)][-(a2)/(90)B(l*r2)]"],
               "radii": "turtle", "width": 0.3, "leaves_per_tip": 2},
        ranges={"constants": _constants(r1=Jitter(0.9, 0.04), r2=Jitter(0.7, 0.1), a1=Jitter(10.0, 0.3),
                                        a2=Jitter(60.0, 0.15), wr=Jitter(0.707, 0.05)),
                "iterations": IntRange(9, 11), "step": Uniform(1.5, 2.2), "angle_jitter": Uniform(0.0, 5.0),
                "tropism": _droop(0.0, 0.06), "leaf_size": Uniform(0.1, 0.16)},
    ),
    Preset(
        name="lsystem_stochastic_shrub",
        generator="lsystem",
        description="ABOP fig. 1.27 stochastic plant in 3D, with alternate (cherry-like) leaf twigs at the tips",
        fixed={"axiom": "F",
               "rules": ["F -> F[+F]/(r)F[-F]F : 0.33", "F -> F[+F]/(r)F : 0.33", "F -> F[-F]/(r)F : 0.34"],
               "radii": "pipe", "tip_radius": 0.002, "twigs": "alternate"},
        ranges={"constants": _constants(r=Uniform(70.0, 120.0)), "iterations": IntRange(4, 5),
                "angle": Jitter(25.7, 0.15), "step": Uniform(0.035, 0.055), "angle_jitter": Uniform(0.0, 6.0),
                "twig_angle": Uniform(35.0, 55.0), "leaf_size": Uniform(0.04, 0.06)},
    ),
    Preset(
        name="lsystem_dichotomous",
        generator="lsystem",
        description="Thesis 003 example X -> F[-X][+X] in 3D (forks turn 90 degrees each level), opposite leaf twigs",
        fixed={"axiom": "X(1)", "rules": ["X(l) -> F(l)/(90)[-X(l*k)][+X(l*k)]"], "radii": "pipe",
               "tip_radius": 0.004, "twigs": "opposite"},
        ranges={"constants": _constants(k=Uniform(0.72, 0.85)), "iterations": IntRange(7, 9),
                "angle": Choice((30.0, 25.0, 35.0)), "step": Uniform(1.2, 1.8), "angle_jitter": Uniform(2.0, 8.0),
                "tropism": _droop(0.0, 0.05), "twig_step": Uniform(0.04, 0.06), "leaf_size": Uniform(0.05, 0.08)},
    ),
]
