"""The Weber-Penn parameter schema: Sapling's 70 keys (plus a few of ours), their types, ranges and defaults.

`validate(params) -> dict` returns a normalised copy (numbers as floats/ints, shapes as ints, lists of 4) or
raises `ParameterError` naming the key, the value and what is allowed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import ParameterError
from .sapling_keys import BLENDER_ONLY_KEYS, DRAWS, OLD_SAPLING_KEYS, SAPLING_DEFAULTS, draws_semantics

__all__ = ["validate", "SCHEMA", "REALIZED_DRAWS", "SAPLING_KEYS"]


# Sapling's shape menus: the tree's shape may be the custom profile (8); secondary branches and the leaf
# distribution may not (their shape ratio has no custom profile). 9 is the pruning envelope, in no menu.
TREE_SHAPES = (0, 1, 2, 3, 4, 5, 6, 7, 8, 10)
SIDE_SHAPES = (0, 1, 2, 3, 4, 5, 6, 7, 10)


@dataclass(frozen=True)
class Key:
    kind: str          # float, int, bool, shape, enum, float4, int4, color
    low: float | None = None
    high: float | None = None
    default: Any = None
    options: tuple = ()

    def allowed(self) -> str:
        if self.kind == "bool":
            return "true or false"
        if self.kind == "shape":
            return f"a shape id, one of {list(self.options)} (number or numeric string)"
        if self.kind == "enum":
            return f"one of {list(self.options)}"
        what = {"float": "a number", "int": "an integer", "float4": "a list of 4 numbers",
                "int4": "a list of 4 integers", "color": "a list of 3 numbers"}[self.kind]
        return f"{what} in [{self.low:g}, {self.high:g}]"


F4, I4 = "float4", "int4"
# Ranges are what the generator handles, wide enough for every Sapling preset and TreeSketchNet dictionary.
SCHEMA: dict[str, Key] = {
    "attractOut": Key(F4, 0, 1, [0, 0, 0, 0]),
    "attractUp": Key(F4, -20, 20, [0, 0, 0.5, 0.5]),
    "baseSize": Key("float", 0, 1, 0.4),
    "baseSize_s": Key("float", 0, 1, 0.25),
    "baseSplits": Key("int", 0, 10, 0),
    "bevelRes": Key("int", 0, 32, 1),
    "branchDist": Key("float", 0.01, 10, 1.0),
    "branches": Key(I4, 0, 2000, [0, 50, 30, 10]),
    "choiceNegPos1": Key("int", -1, 1, None),
    "choiceNegPos2": Key("int", -1, 1, None),
    "curve": Key(F4, -360, 360, [0, -40, -40, 0]),
    "curveBack": Key(F4, -360, 360, [0, 0, 0, 0]),
    "curveRes": Key(I4, 1, 64, [8, 5, 3, 1]),
    "curveV": Key(F4, -720, 720, None),
    "curveV1": Key(F4, -720, 720, None),
    "curveV2": Key(F4, -720, 720, None),
    "customShape": Key(F4, 0, 1, [0.5, 1.0, 0.3, 0.5]),
    "downAngle": Key(F4, -360, 360, [90, 60, 45, 45]),
    "downAngleV": Key(F4, -360, 360, [0, -50, 10, 10]),
    "horzLeaves": Key("bool", default=True),
    "leafDist": Key("shape", 0, 10, 4, SIDE_SHAPES),
    "leafDownAngle": Key("float", -360, 360, 45),
    "leafDownAngleV": Key("float", -360, 360, 10),
    "leafRotate": Key("float", -360, 360, 137.5),
    "leafRotateV": Key("float", -360, 360, 15),
    "leafScale": Key("float", 0, 100, 0.17),
    "leafScaleT": Key("float", -1, 1, 0),
    "leafScaleV": Key("float", 0, 2, None),
    "leafScaleX": Key("float", 0, 10, 1),
    "leafShape": Key("enum", options=("rect", "hex"), default="hex"),
    "leafangle": Key("float", -360, 360, 0),
    "leaves": Key("int", -100, 10000, 25),
    "length": Key(F4, 0, 10, [1, 0.3, 0.6, 0.45]),
    "lengthV": Key(F4, 0, 1, [0, 0, 0, 0]),
    "levels": Key("int", 1, 4, 3),
    "maxBaseSplits": Key("int", 0, 10, 0),
    "minRadius": Key("float", 0, 1, 0.0015),
    "nrings": Key("int", 0, 100, 0),
    "prune": Key("bool", default=False),
    "pruneBase": Key("float", 0, 1, 0.3),
    "prunePowerHigh": Key("float", -100, 100, 0.5),
    "prunePowerLow": Key("float", -100, 100, 0.001),
    "pruneRatio": Key("float", 0, 1, 1.0),
    "pruneWidth": Key("float", 0.001, 100, 0.4),
    "pruneWidthPeak": Key("float", 0, 1, 0.6),
    "rLastAng": Key(F4, -720, 720, None),
    "rSplits2": Key("float", 0, 1, None),
    "radiusTweak": Key(F4, 0, 10, [1, 1, 1, 1]),
    "ratio": Key("float", 0, 1, 0.015),
    "ratioPower": Key("float", 0, 5, 1.2),
    "resU": Key("int", 1, 64, 4),
    "rootFlare": Key("float", 0, 10, 1.0),
    "rotate": Key(F4, -360, 360, [99.5, 137.5, 137.5, 137.5]),
    "rotateV": Key(F4, -360, 360, [15, 0, 0, 0]),
    "scale": Key("float", 0.001, 1000, 13),
    "scale0": Key("float", 0.001, 100, 1),
    "scaleV": Key("float", -1000, 1000, None),
    "scaleV0": Key("float", 0, 2, None),
    "seed": Key("int", 0, 2**53, 0),
    "segSplits": Key(F4, 0, 3, [0, 0, 0, 0]),
    "shape": Key("shape", 0, 10, 7, TREE_SHAPES),
    "shapeS": Key("shape", 0, 10, 4, SIDE_SHAPES),
    "splitAngle": Key(F4, -360, 360, [0, 0, 0, 0]),
    "splitAngleV": Key(F4, -360, 360, None),
    "splitAngleV1": Key(F4, -360, 360, None),
    "splitAngleV2": Key(F4, -360, 360, None),
    "splitBias": Key("float", -2, 2, 0),
    "splitHeight": Key("float", 0, 1, 0.2),
    "taper": Key(F4, 0, 1, [1, 1, 1, 1]),
    "taperCrown": Key("float", 0, 1, 0),
    "useOldDownAngle": Key("bool", default=False),
    "useParentAngle": Key("bool", default=True),
    # Ours (not among TreeSketchNet's 70 keys): Sapling UI options and presentation.
    "autoTaper": Key("bool", default=True),
    "splitByLen": Key("bool", default=False),  # Sapling's default: TreeSketchNet's dictionaries grew with it
    "closeTip": Key("bool", default=False),
    "rMode": Key("enum", options=("rotate", "random", "original"), default="rotate"),
    "generator": Key("enum", options=("weber_penn",), default="weber_penn"),
    "draws": Key("enum", options=DRAWS, default=None),
    "species": Key("str", default="custom"),
    "bark_color": Key("color", 0, 1, None),
    "leaf_color": Key("color", 0, 1, None),
}

# TreeSketchNet's dictionaries store these random draws of Sapling as realized values; when a dictionary
# lacks one, the generator draws it from the rng it is given.
REALIZED_DRAWS = ("curveV1", "curveV2", "splitAngleV1", "splitAngleV2", "rLastAng", "choiceNegPos1",
                  "choiceNegPos2", "rSplits2", "scaleV", "scaleV0", "leafScaleV")
SAPLING_KEYS = tuple(k for k in SCHEMA if k not in ("autoTaper", "splitByLen", "closeTip", "rMode", "generator",
                                                      "species", "bark_color", "leaf_color", "draws"))
# With `draws: ranges` these are Sapling's variation ranges, drawn as uniform(1 - v, 1 + v) or uniform(-v, v):
# a range is never negative, and a factor's range stays within [0, 1] so the factor stays >= 0.
RANGE_LIMITS = {"scaleV": (0.0, 1000.0), "scaleV0": (0.0, 1.0), "leafScaleV": (0.0, 1.0)}


def _number(key: str, value: Any, spec: Key, integer: bool) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(key, value, spec.allowed())
    if not math.isfinite(value) or (integer and float(value) != int(value)):
        raise ParameterError(key, value, spec.allowed())
    if not (spec.low <= value <= spec.high):
        raise ParameterError(key, value, spec.allowed())
    return int(value) if integer else float(value)


def _check(key: str, value: Any, spec: Key) -> Any:
    kind = spec.kind
    if kind == "bool":
        if not isinstance(value, bool):
            raise ParameterError(key, value, spec.allowed())
        return value
    if kind in ("float", "int"):
        return _number(key, value, spec, kind == "int")
    if kind == "shape":
        try:
            number = int(value) if not isinstance(value, bool) and str(value).strip().lstrip("-").isdigit() else None
        except (TypeError, ValueError):
            number = None
        if number is None or number not in spec.options:
            raise ParameterError(key, value, spec.allowed())
        return number
    if kind == "enum":
        if value not in spec.options:
            raise ParameterError(key, value, spec.allowed())
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise ParameterError(key, value, "a string")
        return value
    size = 3 if kind == "color" else 4
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise ParameterError(key, value, spec.allowed())
    item = Key("int" if kind == "int4" else "float", spec.low, spec.high)
    try:
        return [_number(key, v, item, kind == "int4") for v in value]
    except ParameterError:
        raise ParameterError(key, value, spec.allowed()) from None


def validate(params: dict) -> dict:
    """Check every key of a Weber-Penn dictionary; return a normalised copy with defaults filled in and `draws`
    set (`sapling_keys.draws_semantics`); Blender-only and old Sapling keys are left out of it.

    Realized-draw keys (REALIZED_DRAWS) that are missing stay missing: the generator draws them.
    """
    if not isinstance(params, dict):
        raise ParameterError("params", type(params).__name__, "a JSON object of Weber-Penn parameters")
    semantics = draws_semantics(params)
    unknown = sorted(set(params) - set(SCHEMA) - set(BLENDER_ONLY_KEYS) - set(OLD_SAPLING_KEYS))
    if unknown:
        raise ParameterError(unknown[0], params[unknown[0]], f"a known Weber-Penn key (Sapling's names), e.g. "
                             f"{', '.join(sorted(SAPLING_KEYS)[:6])}, ...")
    out: dict[str, Any] = {}
    # A Sapling dictionary that leaves a key out gets the add-on's default, as Sapling would grow it.
    defaults = {key: spec.default for key, spec in SCHEMA.items()}
    if semantics == "ranges":
        defaults.update(SAPLING_DEFAULTS)
    for key, spec in SCHEMA.items():
        if key in params:
            out[key] = _check(key, params[key], spec)
        elif defaults[key] is not None:
            out[key] = list(defaults[key]) if isinstance(defaults[key], list) else defaults[key]
    out["draws"] = semantics
    if semantics == "ranges":
        for key, (low, high) in RANGE_LIMITS.items():
            if key in out:
                out[key] = _check(key, out[key], Key(SCHEMA[key].kind, low, high))
        return out
    scale_val = out["scale"] + out.get("scaleV", 0.0)
    if scale_val <= 0:
        raise ParameterError("scaleV", out.get("scaleV"), f"a value with scale + scaleV > 0 (scale = {out['scale']})")
    return out
