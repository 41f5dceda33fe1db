"""Sapling's own preset files, loaded as Blender's Sapling add-on loads them.

In: a preset file as the add-on saves it (`<name>.py` holding the `repr` of its settings dict, or
`settings = {...}`), or the same dict as JSON. Out: a dictionary `species.grow` takes, with `draws: ranges` unless
the file says otherwise (`sapling_keys` says what the two readings mean).

The add-on sets every key a preset gives it and uses only its own: a key neither it nor treefarm defines is
ignored (and listed), and so are the stored draws a `draws: ranges` preset carries beside Sapling's ranges
(TreeSketchNet's result presets: `curveV1` beside `curveV`): it grows from the ranges. A preset that says
`draws: realized` keeps its stored draws and ignores the ranges they were drawn from.
"""
from __future__ import annotations

import ast
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ParameterError, PathError
from ..growth import check_describes_a_tree
from .sapling_keys import BLENDER_ONLY_KEYS, OLD_SAPLING_KEYS, RANGE_ONLY_KEYS, REALIZED_ONLY_KEYS, ignored_keys
from .schema import SCHEMA

__all__ = ["read_sapling_preset", "load_sapling_preset", "sapling_preset_from_settings", "SaplingPreset",
           "clamp_to_sapling", "SAPLING_BOUNDS"]

_UNKNOWN = "not a property of Sapling 0.3.4 nor a treefarm key; the add-on sets it and never reads it"
_STORED_DRAW = ("a stored draw (TreeSketchNet's), which the add-on does not know: grown from Sapling's ranges "
                "(curveV, splitAngleV) as the add-on grows it; `draws: realized` keeps it")
_DRAWN_RANGE = "the range the dictionary's stored draws were drawn from: `draws: realized` grows from the draws"


# The hard limits of Sapling 0.3.4's properties (its operator's min and max): Blender clamps a preset's value to
# them when the add-on loads it, so a preset grows as if it held the clamped value (acer's baseSize_s 4.0 is 1.0).
SAPLING_BOUNDS: dict[str, tuple[float | None, float | None]] = {
    "attractOut": (0.0, 1.0), "baseSize": (0.0, 1.0), "baseSize_s": (0.0, 1.0), "baseSplits": (0, None),
    "bevelRes": (0, 32), "branchDist": (0.1, None), "branches": (0, None), "curveRes": (1, None),
    "customShape": (0.01, 1.0), "leafScale": (0.0, None), "leafScaleT": (-1.0, 1.0), "leafScaleV": (0.0, 1.0),
    "leafScaleX": (0.0, None), "length": (1e-6, None), "lengthV": (0.0, 1.0), "levels": (1, 6),
    "minRadius": (0.0, None), "nrings": (0, None), "pruneBase": (0.0, 1.0), "pruneRatio": (0.0, 1.0),
    "pruneWidth": (0.0, None), "pruneWidthPeak": (0.0, None), "radiusTweak": (0.0, 1.0), "ratio": (0.0, None),
    "ratioPower": (0.0, None), "resU": (1, None), "rootFlare": (1.0, None), "scale": (0.0, None),
    "scale0": (0.0, None), "scaleV0": (0.0, 1.0), "segSplits": (0.0, None), "splitHeight": (0.0, 1.0),
    "taper": (0.0, 1.0), "taperCrown": (0.0, None),
}
# Sapling's bounds on scaleV0 and leafScaleV are a range's; with `draws: realized` the keys hold drawn factors.
REALIZED_FACTORS = ("scaleV0", "leafScaleV")


@dataclass(frozen=True)
class SaplingPreset:
    """A Sapling preset file read: the dictionary to grow, the keys of the file that do not change the tree (key ->
    why: Blender-only, old Sapling, unknown keys, and the kind of variation key its `draws` does not read) and the
    values Blender clamps (key -> (in the file, as grown))."""

    params: dict
    ignored: dict[str, str]
    clamped: dict[str, tuple[Any, Any]]


def read_sapling_preset(path: str | Path) -> dict:
    """The dictionary of a Sapling preset file (`load_sapling_preset(path).params`)."""
    return load_sapling_preset(path).params


def load_sapling_preset(path: str | Path) -> SaplingPreset:
    """Read a Sapling preset file (.py as the add-on saves it, or .json) as the add-on loads it: tuples as lists,
    its upgrades of old presets applied (a number `attractUp`, leaf angles taken from the last level), values
    clamped to its properties' limits, and `draws: ranges` unless the file says otherwise. Raises PathError or
    ParameterError naming the file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise PathError(f"cannot read Sapling preset {path}: {exc.strerror or exc}") from None
    raw = _parse(text, path)
    if not isinstance(raw, dict):
        raise ParameterError("preset", type(raw).__name__, f"a dict of Sapling settings in {path}")
    return sapling_preset_from_settings(raw)


def sapling_preset_from_settings(settings: dict) -> SaplingPreset:
    """A Sapling settings dict already read from its file, loaded as the add-on loads it (see
    `load_sapling_preset`); the keys it ignores are left out of the dictionary and listed in `ignored`, except
    the Blender-only and old ones, which `schema.validate` takes and leaves out. A preset whose every key is
    ignored describes no tree and is refused, naming its keys."""
    params = {key: _lists(value) for key, value in settings.items()}
    _upgrade_old_preset(params)
    params.setdefault("draws", "ranges")
    unused = _unused_keys(params)
    check_describes_a_tree(params, ignored=(*BLENDER_ONLY_KEYS, *OLD_SAPLING_KEYS, *unused))
    params = {key: value for key, value in params.items() if key not in unused}
    params, clamped = clamp_to_sapling(params, skip=REALIZED_FACTORS if params["draws"] == "realized" else ())
    return SaplingPreset(params=params, ignored={**ignored_keys(params), **unused}, clamped=clamped)


def _unused_keys(params: dict) -> dict[str, str]:
    """The keys of a preset that neither the add-on nor treefarm grows from, with why: unknown keys, and the one
    kind of variation key its `draws` does not read (stored draws beside ranges, or the ranges beside draws)."""
    unused = {key: _UNKNOWN for key in params
              if key not in SCHEMA and key not in BLENDER_ONLY_KEYS and key not in OLD_SAPLING_KEYS}
    stored = [key for key in REALIZED_ONLY_KEYS if key in params]
    if params["draws"] == "ranges":
        unused.update({key: _STORED_DRAW for key in stored})
    elif params["draws"] == "realized" and stored:
        unused.update({key: _DRAWN_RANGE for key in RANGE_ONLY_KEYS if key in params})
    return unused


def clamp_to_sapling(params: dict, skip: tuple[str, ...] = ()) -> tuple[dict, dict[str, tuple[Any, Any]]]:
    """A copy of `params` with every number (or list item) outside SAPLING_BOUNDS clamped into them, and what was
    clamped (key -> (before, after)); keys in `skip` are left as they are. Values of other types are left for
    validation to name."""
    out, clamped = dict(params), {}
    for key, (low, high) in SAPLING_BOUNDS.items():
        if key not in params or key in skip:
            continue
        value = params[key]
        items = value if isinstance(value, list) else [value]
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in items):
            continue
        fixed = [_clamp(v, low, high) for v in items]
        if fixed != items:
            out[key] = fixed if isinstance(value, list) else fixed[0]
            clamped[key] = (value, out[key])
    return out, clamped


def _parse(text: str, path: Path) -> Any:
    """The literal a preset file holds: JSON, a bare dict literal, or a `settings = {...}` assignment. Never run."""
    if path.suffix == ".json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise ParameterError("preset", path.name, f"a JSON object ({exc.msg} at line {exc.lineno})") from None
    try:
        tree = ast.parse(text, filename=str(path))
    except SyntaxError as exc:
        raise ParameterError("preset", path.name, f"a Python literal dict (syntax error at line {exc.lineno})") \
            from None
    for node in tree.body:
        if isinstance(node, ast.Expr):
            value = node.value
        elif isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "settings"
                                                  for t in node.targets):
            value = node.value
        else:
            continue
        try:
            return ast.literal_eval(value)
        except ValueError:
            raise ParameterError("preset", path.name, "a dict of literal values (numbers, strings, lists)") \
                from None
    raise ParameterError("preset", path.name, "a file holding a Sapling settings dict ({...} or settings = {...})")


def _clamp(value: float, low: float | None, high: float | None) -> float:
    """`value` within [low, high] (a None bound is open), an int kept an int where the bound is whole."""
    clamped = value
    if low is not None and clamped < low:
        clamped = low
    if high is not None and clamped > high:
        clamped = high
    return int(clamped) if isinstance(value, int) and float(clamped).is_integer() else clamped


def _lists(value: Any) -> Any:
    return [_lists(v) for v in value] if isinstance(value, (list, tuple)) else value


def _upgrade_old_preset(params: dict) -> None:
    """What Sapling's own preset import does to presets saved by older versions of the add-on."""
    if isinstance(params.get("attractUp"), (int, float)) and not isinstance(params["attractUp"], bool):
        value = params["attractUp"]
        params["attractUp"] = [0, 0, value, value]
    if "leafDownAngle" not in params and {"levels", "downAngle", "downAngleV", "rotate", "rotateV"} <= set(params):
        last = min(int(params["levels"]), 3)
        for leaf_key, key in (("leafDownAngle", "downAngle"), ("leafDownAngleV", "downAngleV"),
                              ("leafRotate", "rotate"), ("leafRotateV", "rotateV")):
            if isinstance(params[key], list) and len(params[key]) == 4:
                params[leaf_key] = params[key][last]
