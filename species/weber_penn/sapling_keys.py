"""What the keys of a Weber-Penn dictionary in Sapling's names mean: the two readings of its variation keys, and
the keys treefarm accepts and ignores (they only drive Blender, or older Sapling versions saved them).

A dictionary's `draws` key says how its variation keys are read:
- `realized` (TreeSketchNet's dictionaries and treefarm's presets): `scaleV` is the metres added to `scale`,
  `scaleV0` and `leafScaleV` factors, and `curveV1/2`, `splitAngleV1/2`, `rLastAng`, `choiceNegPos1/2`, `rSplits2`
  the values of Sapling's random draws, stored;
- `ranges` (Sapling's presets): `scaleV`, `scaleV0`, `leafScaleV`, `curveV` and `splitAngleV` are the ranges Sapling
  draws from, each draw made from the tree's generator where Sapling makes it (per tree, stem, segment, split or
  leaf).
Without a `draws` key the keys present decide (`draws_reading`).
"""
from __future__ import annotations

from typing import Any

from ..errors import ParameterError

__all__ = ["DRAWS", "RANGE_ONLY_KEYS", "REALIZED_ONLY_KEYS", "BLENDER_ONLY_KEYS", "OLD_SAPLING_KEYS",
           "SAPLING_DEFAULTS", "draws_reading", "draws_semantics", "reads_as_sapling_preset", "ignored_keys"]

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

_DROPPED = "a property Sapling 0.3.4 no longer defines"
# Keys older Sapling versions saved in their presets; 0.3.4 has commented their properties out, sets them when it
# loads such a preset and never reads them.
OLD_SAPLING_KEYS: dict[str, str] = {
    "startCurv": f"{_DROPPED} (the trunk's start angle); the add-on ignores it",
    "windSpeed": f"{_DROPPED} (the older wind system, now wind and gust); the add-on ignores it",
    "windGust": f"{_DROPPED} (the older wind system, now wind and gust); the add-on ignores it",
}

# Sapling 0.3.4's defaults where they differ from treefarm's: what a `draws: ranges` dictionary that leaves the key
# out grows with (treefarm's own defaults serve `realized` dictionaries, whose presets were made with them).
SAPLING_DEFAULTS: dict[str, Any] = {
    "branches": [50, 30, 10, 10], "curveRes": [3, 5, 3, 1], "curveV": [20, 50, 75, 0],
    "splitAngleV": [0, 0, 0, 0], "scaleV": 3.0, "scaleV0": 0.2, "attractUp": [0, 0, 0, 0], "minRadius": 0.0,
    "rotate": [137.5, 137.5, 137.5, 137.5], "rotateV": [0, 0, 0, 0], "leafRotateV": 0.0, "leafScaleV": 0.0,
    "leafDist": 6, "bevelRes": 0,
}


def draws_reading(params: dict) -> str:
    """`realized` or `ranges`: the dictionary's `draws` key, else `ranges` when it holds a key only Sapling's own
    dictionaries hold (curveV, splitAngleV, a Blender-only key or an old Sapling key), else `realized` (as before
    `draws` existed). Raises ParameterError only for a `draws` value that is neither."""
    explicit = params.get("draws")
    if explicit is not None and explicit not in DRAWS:
        raise ParameterError("draws", explicit, f"one of {list(DRAWS)}")
    sapling = any(k in params for k in (*RANGE_ONLY_KEYS, *BLENDER_ONLY_KEYS, *OLD_SAPLING_KEYS))
    return explicit or ("ranges" if sapling else "realized")


def reads_as_sapling_preset(params: dict) -> bool:
    """Whether a dictionary read from a file loads as a Sapling preset (`sapling_preset_from_settings`): one that
    reads as `ranges`, or that holds Sapling's ranges beside `draws: realized` (a result preset of TreeSketchNet)."""
    return draws_reading(params) == "ranges" or any(k in params for k in RANGE_ONLY_KEYS)


def draws_semantics(params: dict) -> str:
    """`draws_reading(params)`, for a dictionary given as it is (not a preset file): one that mixes the two kinds
    of variation keys is refused, naming one of each."""
    semantics = draws_reading(params)
    realized = [k for k in REALIZED_ONLY_KEYS if k in params]
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
    """The Blender-only and old Sapling keys of a dictionary, each with why treefarm grows the same tree without
    it."""
    reasons = {**BLENDER_ONLY_KEYS, **OLD_SAPLING_KEYS}
    return {key: reasons[key] for key in params if key in reasons}
