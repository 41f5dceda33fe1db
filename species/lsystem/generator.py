"""L-system growth model: validate an `"generator": "lsystem"` dictionary, rewrite, draw with the turtle.

In: a parameter dictionary (schema below) and an rng. Out: a `Skeleton` (Z up, metres, base at the origin).
Grammar in species/lsystem_rewrite.py, turtle in species/turtle.py, tip twigs in species/phyllotaxis.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..errors import ParameterError
from .rewrite import LSystem, RULE_FORM
from .phyllotaxis import PATTERNS, add_twigs
from ..geometry.radii import pipe_model_radii
from ..skeleton import Skeleton
from .turtle import interpret, leaf_cards

__all__ = ["grow", "validate", "SCHEMA", "Field"]


@dataclass(frozen=True)
class Field:
    """One key of the schema: its default, a check returning the normalised value, and what is allowed."""

    default: Any
    check: Callable[[Any], Any]
    allowed: str
    doc: str


def _number(low: float, high: float, low_open: bool = False, integer: bool = False) -> Callable[[Any], Any]:
    def check(value):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError
        if integer and int(value) != value:
            raise TypeError
        value = int(value) if integer else float(value)
        if not math.isfinite(value) or value > high or value < low or (low_open and value == low):
            raise ValueError
        return value
    return check


def _choice(*options: str) -> Callable[[Any], Any]:
    def check(value):
        if value not in options:
            raise ValueError
        return value
    return check


def _string(value):
    if not isinstance(value, str):
        raise TypeError
    return value


def _text(value):
    if not isinstance(value, str) or not value.strip():
        raise TypeError
    return value


def _rules(value):
    if not isinstance(value, (list, tuple)) or not all(isinstance(r, str) for r in value):
        raise TypeError
    return list(value)


def _constants(value):
    if not isinstance(value, dict):
        raise TypeError
    out = {}
    for name, number in value.items():
        if not (isinstance(name, str) and name.isidentifier()) or isinstance(number, bool) \
                or not isinstance(number, (int, float)) or not math.isfinite(number):
            raise ValueError
        out[name] = float(number)
    return out


def _vector3(limit: float) -> Callable[[Any], Any]:
    def check(value):
        if not isinstance(value, (list, tuple)) or len(value) != 3 \
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
            raise TypeError
        vector = [float(v) for v in value]
        if not all(math.isfinite(v) for v in vector) or math.hypot(*vector) > limit:
            raise ValueError
        return vector
    return check


SCHEMA: dict[str, Field] = {
    "generator": Field("lsystem", _choice("lsystem"), "'lsystem'", "which growth model reads this dictionary"),
    "species": Field("", _string, "a string", "preset name, for the record"),
    "seed": Field(0, _number(0, 2**63 - 1, integer=True), "an integer >= 0", "seeds every random draw"),
    "axiom": Field(None, _text, "a non-empty module string such as 'X' or 'A(1, 10)'", "the start string"),
    "rules": Field([], _rules, f"a list of rule strings, each {RULE_FORM}", "the productions"),
    "constants": Field({}, _constants, "an object of name -> finite number", "names usable in rules"),
    "iterations": Field(None, _number(0, 30, integer=True), "an integer in [0, 30]", "rewriting steps"),
    "angle": Field(25.0, _number(0, 180), "degrees in [0, 180]", "turn of a bare + - & ^ \\ /"),
    "angle_jitter": Field(0.0, _number(0, 90), "degrees in [0, 90]", "uniform noise added to every turn"),
    "step": Field(0.1, _number(0, 100, low_open=True), "metres in (0, 100]", "length of a bare F; F(x) = x*step"),
    "step_jitter": Field(0.0, _number(0, 0.9), "a fraction in [0, 0.9]", "relative noise on every move"),
    "width": Field(0.1, _number(0, 10, low_open=True), "metres in (0, 10]", "starting turtle width (diameter)"),
    "width_ratio": Field(0.7, _number(0, 1, low_open=True), "a factor in (0, 1]", "what a bare ! multiplies by"),
    "radii": Field("pipe", _choice("pipe", "turtle"), "'pipe' or 'turtle'",
                   "pipe model from the tips (digest 1.7) or the turtle width (! driven)"),
    "tip_radius": Field(0.004, _number(0, 1, low_open=True), "metres in (0, 1]", "pipe model tip radius"),
    "pipe_exponent": Field(2.5, _number(2, 3), "a number in [2, 3]", "pipe model exponent n"),
    "tropism": Field([0.0, 0.0, 0.0], _vector3(1.0), "a list of 3 numbers of length <= 1",
                     "bending vector; [0, 0, -0.1] droops, [0, 0, 0.1] lifts"),
    "leaves_per_tip": Field(2, _number(0, 16, integer=True), "an integer in [0, 16]",
                            "leaf cards at each branch tip (when twigs is 'none')"),
    "leaf_size": Field(0.08, _number(0, 2, low_open=True), "metres in (0, 2]", "leaf card length"),
    "leaf_aspect": Field(0.5, _number(0, 4, low_open=True), "a ratio in (0, 4]", "leaf width / length"),
    "leaf_angle": Field(40.0, _number(0, 90), "degrees in [0, 90]", "tilt of tip leaves away from the branch"),
    "twigs": Field("none", _choice("none", *PATTERNS), f"one of {['none', *PATTERNS]}",
                   "phyllotaxis twig-and-leaf modules grown at every tip"),
    "twig_angle": Field(45.0, _number(0, 90), "degrees in [0, 90]", "branching angle inside a twig"),
    "twig_step": Field(0.04, _number(0, 1, low_open=True), "metres in (0, 1]", "internode length inside a twig"),
    "max_modules": Field(400_000, _number(1, 5_000_000, integer=True), "an integer in [1, 5000000]",
                         "rewriting stops with an error past this string length"),
}


def validate(params: dict) -> dict:
    """A complete, normalised copy of `params` (defaults filled in); raises ParameterError naming the key."""
    if not isinstance(params, dict):
        raise ParameterError("params", type(params).__name__, "a JSON object (dict) of parameters")
    unknown = sorted(set(params) - set(SCHEMA))
    if unknown:
        raise ParameterError(unknown[0], params[unknown[0]], f"a known key: {', '.join(sorted(SCHEMA))}")
    out = {}
    for key, field in SCHEMA.items():
        if key not in params:
            if field.default is None:
                raise ParameterError(key, None, f"{field.allowed} (required)")
            out[key] = field.default
            continue
        try:
            out[key] = field.check(params[key])
        except (TypeError, ValueError):
            raise ParameterError(key, params[key], field.allowed) from None
    return out


def _tip_leaves(path, tips: np.ndarray, p: dict, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """`leaves_per_tip` cards around each tip, evenly rolled from a random start, leaning `leaf_angle`."""
    count = p["leaves_per_tip"]
    if count == 0 or len(tips) == 0:
        return np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int32)
    start = rng.uniform(0, 2 * np.pi, len(tips))
    roll = (start[:, None] + 2 * np.pi * np.arange(count) / count).ravel()
    node = np.repeat(tips, count)
    cards = leaf_cards(path.positions[node], path.frames[node], p["leaf_size"], p["leaf_size"] * p["leaf_aspect"],
                       p["leaf_angle"], roll)
    return cards, node.astype(np.int32)


def grow(params: dict, rng: np.random.Generator) -> Skeleton:
    """Grow the skeleton an L-system dictionary describes; same dictionary and rng state, same skeleton."""
    p = validate(params)
    system = LSystem.parse(p["axiom"], p["rules"], p["constants"])
    modules = system.derive(p["iterations"], rng, p["max_modules"])
    path = interpret(modules, angle=p["angle"], step=p["step"], width=p["width"], width_ratio=p["width_ratio"],
                     rng=rng, tropism=p["tropism"], angle_jitter=p["angle_jitter"], step_jitter=p["step_jitter"])
    if len(path.positions) < 2:
        raise ParameterError("axiom", p["axiom"], "a grammar whose string draws at least one F after "
                                                  f"{p['iterations']} iterations")
    if p["radii"] == "pipe":
        radius = pipe_model_radii(path.parent, p["tip_radius"], p["pipe_exponent"])
    else:
        radius = path.width / 2
    symbol_leaves = leaf_cards(path.positions[path.leaf_node], path.leaf_frames,
                               p["leaf_size"] * path.leaf_scale, p["leaf_size"] * p["leaf_aspect"] * path.leaf_scale,
                               0.0, 0.0)
    tip_leaves, tip_nodes = (_tip_leaves(path, path.tips, p, rng) if p["twigs"] == "none"
                             else (np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int32)))
    skeleton = Skeleton(positions=path.positions, parent=path.parent, radius=radius, order=path.order,
                        leaves=np.concatenate([symbol_leaves, tip_leaves]),
                        leaf_node=np.concatenate([path.leaf_node, tip_nodes]))
    if p["twigs"] != "none":
        skeleton = add_twigs(skeleton, p["twigs"], rng, angle=p["twig_angle"], step=p["twig_step"],
                             leaf_size=p["leaf_size"], leaf_aspect=p["leaf_aspect"])
    return skeleton
