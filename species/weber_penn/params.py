"""The Weber-Penn parameters as one frozen object: Sapling's keys named and typed, per stem level where Sapling
keeps four values, with the realized draws and the values derived from them (tree scale, tapers).

In: `schema.validate`'s output and the rng that draws what the dictionary lacks. Out: `WeberPennParams`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .schema import validate
from .shapes import auto_taper

__all__ = ["WeberPennParams", "StemLevelParams", "LeafParams", "PruneParams", "RealizedDraws"]

TAU = 2 * np.pi


@dataclass(frozen=True)
class StemLevelParams:
    """Sapling's per-level keys for one stem level (0 = trunk). Angles in degrees, as Sapling stores them."""

    curve_res: int               # curveRes: segments per stem
    length: float                # length: stem length over its parent's (the trunk: over the tree scale)
    length_variation: float      # lengthV: relative spread of the segment length
    curve: float                 # curve: degrees of bend over the stem
    curve_back: float            # curveBack: degrees the upper half bends back
    seg_splits: float            # segSplits: splits per segment
    split_angle: float           # splitAngle: degrees between a split and its stem
    rotate: float                # rotate: degrees between successive stems around their parent
    rotate_variation: float      # rotateV
    down_angle: float            # downAngle: degrees between a stem and its parent
    down_angle_variation: float  # downAngleV
    attract_up: float            # attractUp: turn toward world up per segment (negative: droop)
    attract_out: float           # attractOut: turn away from the trunk axis
    radius_tweak: float          # radiusTweak: factor on the start radius
    taper: float                 # taper: radius taper over the stem, after autoTaper where that is on
    branches: int                # branches: stems of this level per parent stem (unused for the trunk)


@dataclass(frozen=True)
class LeafParams:
    """Sapling's leaf keys. Angles in degrees."""

    count: int                   # leaves: per last-level stem; negative: a fan of -count at each point
    distribution: int            # leafDist: shape id of the leaf density along a stem
    rotate: float                # leafRotate: degrees between successive leaves around the stem
    rotate_variation: float      # leafRotateV
    down_angle: float            # leafDownAngle: degrees between a leaf and its stem
    down_angle_variation: float  # leafDownAngleV
    tilt: float                  # leafangle: degrees the card is tilted about its width
    horizontal: bool             # horzLeaves: turn each card's face toward the sky
    scale: float                 # leafScale: metres, card length
    scale_taper: float           # leafScaleT: size change from stem base to tip, in [-1, 1]
    scale_x: float               # leafScaleX: width over length


@dataclass(frozen=True)
class PruneParams:
    """Sapling's pruning envelope: stems are shortened until their tips lie inside it."""

    enabled: bool       # prune
    base: float         # pruneBase: fraction of the height below the envelope
    ratio: float        # pruneRatio: 1 = prune fully, 0 = not at all
    width: float        # pruneWidth: envelope width over the tree scale
    width_peak: float   # pruneWidthPeak: relative height of the widest point
    power_high: float   # prunePowerHigh: curvature of the envelope above the peak
    power_low: float    # prunePowerLow: curvature below it


@dataclass(frozen=True)
class RealizedDraws:
    """TreeSketchNet's stored random draws of Sapling (see generator's docstring), or fresh ones from the rng.

    Per-level arrays are (4,) float64 radians, read-only.
    """

    scale_offset: float             # scaleV: metres added to scale
    trunk_radius_factor: float      # scaleV0: factor on the trunk radius
    leaf_size_factor: float         # leafScaleV: factor on the leaf size
    curve_variation: np.ndarray     # curveV1: bend variation in the bending plane, per level
    curve_variation_across: np.ndarray  # curveV2: bend variation across it
    split_angle_variation: np.ndarray   # splitAngleV1
    spread_angle_variation: np.ndarray  # splitAngleV2
    first_split_turn: np.ndarray    # rLastAng: rotation of a stem's first split
    split_angle_sign: float         # choiceNegPos1 as +1 or -1
    spread_angle_sign: float        # choiceNegPos2 as +1 or -1
    split_threshold: float | None   # rSplits2: what a split probability must exceed; None: drawn per decision
    ranges: SaplingRanges | None = None  # with `draws: ranges`: what growth draws per stem, segment, split, leaf

    @classmethod
    def from_validated(cls, validated: dict, rng: np.random.Generator) -> RealizedDraws:
        if validated["draws"] == "ranges":
            return cls.from_ranges(validated, rng)
        return cls(
            scale_offset=validated.get("scaleV", 0.0),
            trunk_radius_factor=validated.get("scaleV0", 1.0),
            leaf_size_factor=validated.get("leafScaleV", 1.0),
            curve_variation=_per_level_radians(validated, "curveV1"),
            curve_variation_across=_per_level_radians(validated, "curveV2"),
            split_angle_variation=_per_level_radians(validated, "splitAngleV1"),
            spread_angle_variation=_per_level_radians(validated, "splitAngleV2"),
            first_split_turn=_per_level_radians(validated, "rLastAng", rng),
            split_angle_sign=_sign(validated.get("choiceNegPos1", 1)),
            spread_angle_sign=_sign(validated.get("choiceNegPos2", 1)),
            split_threshold=validated.get("rSplits2"),
        )

    @classmethod
    def from_ranges(cls, validated: dict, rng: np.random.Generator) -> RealizedDraws:
        """Sapling's per-tree draws from its ranges (scale + uniform(-scaleV, scaleV), trunk radius times
        uniform(1 - scaleV0, 1 + scaleV0)); the rest is left to growth, in `ranges`."""
        scale_range, radius_range = validated.get("scaleV", 0.0), validated.get("scaleV0", 0.0)
        zeros = np.zeros(4)
        zeros.setflags(write=False)
        return cls(
            scale_offset=float(rng.uniform(-scale_range, scale_range)) if scale_range else 0.0,
            trunk_radius_factor=float(rng.uniform(1 - radius_range, 1 + radius_range)) if radius_range else 1.0,
            leaf_size_factor=1.0, curve_variation=zeros, curve_variation_across=zeros, split_angle_variation=zeros,
            spread_angle_variation=zeros, first_split_turn=zeros, split_angle_sign=1.0, spread_angle_sign=1.0,
            split_threshold=None, ranges=SaplingRanges.from_validated(validated))


@dataclass(frozen=True)
class SaplingRanges:
    """The variation ranges of a `draws: ranges` dictionary that growth draws from, where Sapling draws them:
    curvature per segment, split and spread angles (and their signs) per split, the first split's turn per stem,
    the trunk's split turn per split, leaf size per leaf. Per-level arrays are (4,) radians, read-only."""

    curve: np.ndarray            # curveV: a segment bends by uniform(0, curveV / curveRes) in and across its plane
    split_angle: np.ndarray      # splitAngleV: split and spread angles are splitAngle + uniform(-v, v), sign random
    trunk_turn: float            # rotateV[0], degrees: each trunk split turns by rotate[0] + uniform(-v, v)
    leaf_scale: float            # leafScaleV: each leaf's size times uniform(1 - v, 1 + v)

    @classmethod
    def from_validated(cls, validated: dict) -> SaplingRanges:
        return cls(curve=_per_level_radians(validated, "curveV"),
                   split_angle=_per_level_radians(validated, "splitAngleV"),
                   trunk_turn=float(validated["rotateV"][0]), leaf_scale=float(validated.get("leafScaleV", 0.0)))


def _per_level_radians(validated: dict, key: str, rng: np.random.Generator | None = None) -> np.ndarray:
    """(4,) read-only radians of a per-level draw (degrees in the dictionary); where the dictionary lacks it,
    zeros, or with `rng` a fresh uniform draw in [0, 2 pi)."""
    if key in validated:
        values = np.radians(validated[key])
    elif rng is None:
        values = np.zeros(4)
    else:
        values = rng.uniform(0, TAU, 4)
    values.setflags(write=False)
    return values


def _sign(choice: int) -> float:
    """TreeSketchNet's choiceNegPos: 1 is positive, 0 or -1 negative."""
    return 1.0 if choice > 0 else -1.0


@dataclass(frozen=True)
class WeberPennParams:
    """One validated Weber-Penn dictionary, read once: what every growth step takes instead of the raw dict."""

    levels: int                  # levels: stem levels, 1 (trunk only) to 4
    stem_levels: tuple[StemLevelParams, ...]  # 4 levels, index = branch order
    leaves: LeafParams
    prune: PruneParams
    draws: RealizedDraws
    tree_scale: float            # metres: scale + scaleV, nudged off zero
    trunk_scale: float           # scale0: factor on the trunk radius
    ratio: float                 # ratio: trunk radius over the tree scale
    ratio_power: float           # ratioPower: how fast radii shrink from level to level
    min_radius: float            # minRadius: metres
    root_flare: float            # rootFlare: factor on the trunk's first radius
    base_size: float             # baseSize: fraction of the trunk without branches
    base_size_shrink: float      # baseSize_s: factor on the base size per level
    base_splits: int             # baseSplits: splits at the trunk's first segment
    split_bias: float            # splitBias: more trunk splits toward the top (> 0) or the base (< 0)
    split_height: float          # splitHeight: fraction of the trunk below its first split
    split_by_length: bool        # splitByLen: branch split probability grows with segment length
    taper_crown: float           # taperCrown: shortens leaning trunk segments
    close_tip: bool              # closeTip: the last level ends in radius 0
    shape: int                   # shape: shape id of first-level branch lengths along the trunk
    side_shape: int              # shapeS: shape id of higher-level branch lengths
    custom_shape: tuple[float, ...]  # customShape: (4,) profile of shape 8
    rotate_mode: str             # rMode: how first-level branches turn around the trunk
    old_down_angle: bool         # useOldDownAngle: Sapling's earlier down-angle variation
    parent_angle: bool           # useParentAngle: first-level branches follow the trunk's lean
    branch_distribution: float   # branchDist: spacing of first-level branches up the trunk
    rings: int                   # nrings: first-level branches in whorls of this many heights (0: off)

    @classmethod
    def from_dict(cls, params: dict, rng: np.random.Generator) -> WeberPennParams:
        """Validate a Sapling dictionary (ParameterError names a bad key) and read it."""
        return cls.from_validated(validate(params), rng)

    @classmethod
    def from_validated(cls, validated: dict, rng: np.random.Generator) -> WeberPennParams:
        """Read `schema.validate`'s output; draws the realized draws it lacks from `rng`."""
        draws = RealizedDraws.from_validated(validated, rng)
        tree_scale = validated["scale"] + draws.scale_offset
        tree_scale += np.copysign(1e-6, tree_scale)  # a nudge away from zero that every output depends on
        return cls(
            levels=validated["levels"], stem_levels=_stem_levels(validated), leaves=_leaf_params(validated),
            prune=_prune_params(validated), draws=draws, tree_scale=tree_scale, trunk_scale=validated["scale0"],
            ratio=validated["ratio"], ratio_power=validated["ratioPower"], min_radius=validated["minRadius"],
            root_flare=validated["rootFlare"], base_size=validated["baseSize"],
            base_size_shrink=validated["baseSize_s"], base_splits=validated["baseSplits"],
            split_bias=validated["splitBias"], split_height=validated["splitHeight"],
            split_by_length=validated["splitByLen"], taper_crown=validated["taperCrown"],
            close_tip=validated["closeTip"], shape=validated["shape"], side_shape=validated["shapeS"],
            custom_shape=tuple(validated["customShape"]), rotate_mode=validated["rMode"],
            old_down_angle=validated["useOldDownAngle"], parent_angle=validated["useParentAngle"],
            branch_distribution=validated["branchDist"], rings=validated["nrings"],
        )

    def stem_lengths(self) -> np.ndarray:
        """(4,) float64, each level's `length` key."""
        return np.array([level.length for level in self.stem_levels], np.float64)


def _stem_levels(validated: dict) -> tuple[StemLevelParams, ...]:
    if validated["autoTaper"]:
        taper = auto_taper(validated["length"], validated["taper"], validated["shape"], validated["shapeS"],
                           validated["levels"], validated["customShape"])
    else:
        taper = list(validated["taper"])
    keys = {"curve_res": "curveRes", "length": "length", "length_variation": "lengthV", "curve": "curve",
            "curve_back": "curveBack", "seg_splits": "segSplits", "split_angle": "splitAngle", "rotate": "rotate",
            "rotate_variation": "rotateV", "down_angle": "downAngle", "down_angle_variation": "downAngleV",
            "attract_up": "attractUp", "attract_out": "attractOut", "radius_tweak": "radiusTweak",
            "branches": "branches"}
    return tuple(StemLevelParams(taper=taper[order], **{name: validated[key][order] for name, key in keys.items()})
                 for order in range(4))


def _leaf_params(validated: dict) -> LeafParams:
    return LeafParams(
        count=validated["leaves"], distribution=validated["leafDist"], rotate=validated["leafRotate"],
        rotate_variation=validated["leafRotateV"], down_angle=validated["leafDownAngle"],
        down_angle_variation=validated["leafDownAngleV"], tilt=validated["leafangle"],
        horizontal=validated["horzLeaves"], scale=validated["leafScale"], scale_taper=validated["leafScaleT"],
        scale_x=validated["leafScaleX"])


def _prune_params(validated: dict) -> PruneParams:
    return PruneParams(
        enabled=validated["prune"], base=validated["pruneBase"], ratio=validated["pruneRatio"],
        width=validated["pruneWidth"], width_peak=validated["pruneWidthPeak"],
        power_high=validated["prunePowerHigh"], power_low=validated["prunePowerLow"])
