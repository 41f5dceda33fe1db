"""Sapling's own preset files, and the two readings of a Weber-Penn dictionary's variation keys.

In: a preset file as Blender's Sapling add-on saves it (`<name>.py` holding the `repr` of its settings dict, or
`settings = {...}`), or the same dict as JSON. Out: a dictionary `species.grow` takes, with `draws: ranges`.

A dictionary's `draws` key says how its variation keys are read:
- `realized` (TreeSketchNet's dictionaries and treefarm's presets): `scaleV` is the metres added to `scale`,
  `scaleV0` and `leafScaleV` factors, and `curveV1/2`, `splitAngleV1/2`, `rLastAng`, `choiceNegPos1/2`, `rSplits2`
  the values of Sapling's random draws, stored;
- `ranges` (Sapling's presets): `scaleV`, `scaleV0`, `leafScaleV`, `curveV` and `splitAngleV` are the ranges Sapling
  draws from, each draw made from the tree's generator where Sapling makes it (per tree, stem, segment, split or
  leaf).
Without a `draws` key the keys present decide (`draws_semantics`). Keys that only drive Blender (UI, armature, wind
animation) are accepted and ignored; `ignored_keys` names them with the reason.
"""
from __future__ import annotations

import ast
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ParameterError, PathError

__all__ = ["read_sapling_preset", "load_sapling_preset", "sapling_preset_from_settings", "SaplingPreset",
           "draws_semantics", "ignored_keys", "clamp_to_sapling", "BLENDER_ONLY_KEYS", "RANGE_ONLY_KEYS",
           "REALIZED_ONLY_KEYS", "DRAWS", "SAPLING_BOUNDS", "SAPLING_DEFAULTS"]

DRAWS = ("realized", "ranges")

# Sapling's range keys with no realized counterpart of the same name (TreeSketchNet stores curveV1/curveV2 and
# splitAngleV1/splitAngleV2 instead).
RANGE_ONLY_KEYS = ("curveV", "splitAngleV")
# Stored draws that Sapling's own dictionaries never hold.
REALIZED_ONLY_KEYS = ("curveV1", "curveV2", "splitAngleV1", "splitAngleV2", "rLastAng", "choiceNegPos1",
                      "choiceNegPos2", "rSplits2")

_ANIMATION = "drives Blender's wind animation of the armature, not the tree's shape"
_ARMATURE = "drives the armature Sapling can rig the tree with, not the tree's shape"
# Keys of Sapling 0.3.4's presets that only drive Blender, and why treefarm grows the same tree without them.
BLENDER_ONLY_KEYS: dict[str, str] = {
    "af1": _ANIMATION, "af2": _ANIMATION, "af3": _ANIMATION, "gust": _ANIMATION, "gustF": _ANIMATION,
    "wind": _ANIMATION, "armAnim": _ANIMATION, "leafAnim": _ANIMATION, "frameRate": _ANIMATION,
    "loopFrames": _ANIMATION,
    "useArm": _ARMATURE, "armLevels": _ARMATURE, "boneStep": _ARMATURE, "previewArm": _ARMATURE,
    "makeMesh": "converts Blender's curve object to a mesh; treefarm always writes a mesh",
    "bevel": "gives Blender's curve its thickness; treefarm's bark is always a tube mesh",
    "handleType": "Blender's Bezier handle type for the stem curves; treefarm's stems are polylines of curveRes "
                  "segments, meshed as tubes",
    "showLeaves": "Blender's switch to add the leaf mesh; treefarm always grows the leaves (`leaves: 0` for none)",
    "bend": "leaf bend of Sapling before 0.3, reset to 0 by the add-on when it loads a preset",
}


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


# Sapling 0.3.4's defaults where they differ from treefarm's: what a `draws: ranges` dictionary that leaves the key
# out grows with (treefarm's own defaults serve `realized` dictionaries, whose presets were made with them).
SAPLING_DEFAULTS: dict[str, Any] = {
    "branches": [50, 30, 10, 10], "curveRes": [3, 5, 3, 1], "curveV": [20, 50, 75, 0],
    "splitAngleV": [0, 0, 0, 0], "scaleV": 3.0, "scaleV0": 0.2, "attractUp": [0, 0, 0, 0], "minRadius": 0.0,
    "rotate": [137.5, 137.5, 137.5, 137.5], "rotateV": [0, 0, 0, 0], "leafRotateV": 0.0, "leafScaleV": 0.0,
    "leafDist": 6, "bevelRes": 0,
}


@dataclass(frozen=True)
class SaplingPreset:
    """A Sapling preset file read: the dictionary to grow, the Blender-only keys it holds (key -> why they do not
    change the tree) and the values Blender clamps (key -> (in the file, as grown))."""

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
    `load_sapling_preset`)."""
    params = {key: _lists(value) for key, value in settings.items()}
    _upgrade_old_preset(params)
    params.setdefault("draws", "ranges")
    params, clamped = clamp_to_sapling(params)
    return SaplingPreset(params=params, ignored=ignored_keys(params), clamped=clamped)


def clamp_to_sapling(params: dict) -> tuple[dict, dict[str, tuple[Any, Any]]]:
    """A copy of `params` with every number (or list item) outside SAPLING_BOUNDS clamped into them, and what was
    clamped (key -> (before, after)). Values of other types are left for validation to name."""
    out, clamped = dict(params), {}
    for key, (low, high) in SAPLING_BOUNDS.items():
        if key not in params:
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


def draws_semantics(params: dict) -> str:
    """`realized` or `ranges`: the dictionary's `draws` key, else `ranges` when it holds a key only Sapling's own
    dictionaries hold (curveV, splitAngleV or a Blender-only key), else `realized` (as before `draws` existed).
    A dictionary that mixes the two kinds of keys is refused, naming one of each."""
    explicit = params.get("draws")
    if explicit is not None and explicit not in DRAWS:
        raise ParameterError("draws", explicit, f"one of {list(DRAWS)}")
    sapling = [k for k in (*RANGE_ONLY_KEYS, *BLENDER_ONLY_KEYS) if k in params]
    realized = [k for k in REALIZED_ONLY_KEYS if k in params]
    semantics = explicit or ("ranges" if sapling else "realized")
    if semantics == "ranges" and realized:
        raise ParameterError(realized[0], params[realized[0]],
                             "no stored draw with `draws: ranges` (Sapling's own keys: curveV, splitAngleV); "
                             "drop it, or set `draws: realized`")
    range_only = [k for k in RANGE_ONLY_KEYS if k in params]
    if semantics == "realized" and range_only:
        raise ParameterError(range_only[0], params[range_only[0]],
                             "no Sapling range with `draws: realized` (its stored draws: curveV1/curveV2, "
                             "splitAngleV1/splitAngleV2); drop it, or set `draws: ranges`")
    return semantics


def ignored_keys(params: dict) -> dict[str, str]:
    """The Blender-only keys of a dictionary, each with why treefarm grows the same tree without it."""
    return {key: BLENDER_ONLY_KEYS[key] for key in params if key in BLENDER_ONLY_KEYS}
