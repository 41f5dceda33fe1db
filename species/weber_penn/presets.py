"""Weber-Penn species presets: TreeSketchNet's five species and classic Weber & Penn (1995) trees.

Each preset fixes the keys that identify its species and samples the rest (TreeSketchNet's fixed/unfixed split):
continuous keys scale by U(0.75, 1.25) of their base, a few angles shift by a few degrees, forks and whorls vary by
whole numbers, and Sapling's own random draws are drawn and recorded so the dictionary alone rebuilds the tree.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..presets import Jitter, Preset
from .schema import SCHEMA

__all__ = ["PRESETS", "make_preset"]

# Shared starting point; every preset overrides what makes its species.
_BASE: dict[str, Any] = {
    "attractOut": [0, 0, 0, 0], "attractUp": [0, 0, 0.5, 0.5], "baseSize": 0.4, "baseSize_s": 0.25,
    "baseSplits": 0, "bevelRes": 1, "branchDist": 1.0, "branches": [0, 50, 30, 10], "curve": [0, -40, -40, 0],
    "curveBack": [0, 0, 0, 0], "curveRes": [8, 5, 3, 1], "customShape": [0.5, 1.0, 0.3, 0.5],
    "downAngle": [90, 60, 45, 45], "downAngleV": [0, -50, 10, 10], "horzLeaves": True, "leafDist": "4",
    "leafDownAngle": 45.0, "leafDownAngleV": 10.0, "leafRotate": 137.5, "leafRotateV": 15.0, "leafScale": 0.17,
    "leafScaleT": 0.0, "leafScaleX": 1.0, "leafShape": "hex", "leafangle": 0.0, "leaves": 25,
    "length": [1, 0.3, 0.6, 0.45], "lengthV": [0, 0, 0, 0], "levels": 3, "maxBaseSplits": 0,
    "minRadius": 0.0015, "nrings": 0, "prune": False, "pruneBase": 0.3, "prunePowerHigh": 0.5,
    "prunePowerLow": 0.001, "pruneRatio": 1.0, "pruneWidth": 0.4, "pruneWidthPeak": 0.6,
    "radiusTweak": [1, 1, 1, 1], "ratio": 0.015, "ratioPower": 1.2, "resU": 4, "rootFlare": 1.0,
    "rotate": [99.5, 137.5, 137.5, 137.5], "rotateV": [0, 0, 0, 0], "scale": 13.0, "scale0": 1.0,
    "segSplits": [0, 0, 0, 0], "shape": "7", "shapeS": "4", "splitAngle": [0, 0, 0, 0], "splitBias": 0.0,
    "splitHeight": 0.2, "taper": [1, 1, 1, 1], "taperCrown": 0.0, "useOldDownAngle": False,
    "useParentAngle": True,
    # Our presets were shaped with branch splits scaled by segment length (Sapling's default is off).
    "splitByLen": True,
}

# Keys drawn per tree unless a preset fixes them: multiplicative jitter (TreeSketchNet's unfixed parameters).
_RELATIVE = ("scale", "length", "branches", "leafScale", "leaves", "baseSize", "attractUp", "curve",
             "downAngle", "splitAngle", "ratio")
_ANGULAR = {"rotate": 8.0, "leafDownAngle": 10.0, "leafRotate": 10.0}


def _jitter(key: str, base, rel: float) -> Jitter:
    spec = SCHEMA[key]
    integer = spec.kind in ("int", "int4")
    return Jitter(base, rel=rel, low=spec.low, high=spec.high, integer=integer)


def make_preset(name: str, description: str, overrides: dict, *, scale_var: float, curve_var, split_var=(0, 0, 0, 0),
                radius_var: float = 0.1, leaf_var: float = 0.15, rel: float = 0.2, fixed_keys: tuple = (),
                fork_max: int = 0, whorls: bool = False, bark=(0.36, 0.27, 0.19), leaf=(0.24, 0.45, 0.14)) -> Preset:
    """A Sapling template: `overrides` on the shared base, `fixed_keys` never jittered, realized draws sampled."""
    base = {**_BASE, **overrides, "bark_color": list(bark), "leaf_color": list(leaf)}
    ranges: dict[str, Any] = {}
    for key in _RELATIVE:
        if key not in fixed_keys:
            ranges[key] = _jitter(key, base[key], rel)
    for key, shift in _ANGULAR.items():
        if key not in fixed_keys:
            spec = SCHEMA[key]
            ranges[key] = Jitter(base[key], rel=0.0, add=shift, low=spec.low, high=spec.high)
    if fork_max:
        ranges["baseSplits"] = lambda rng, params, hi=fork_max: int(rng.integers(0, hi + 1))
        base["maxBaseSplits"] = fork_max
    if whorls:
        ranges["nrings"] = lambda rng, params, n=base["nrings"]: int(max(1, n + rng.integers(-2, 3)))
    cv = np.asarray(curve_var, float)
    sv = np.asarray(split_var, float)
    ranges.update({
        # Sapling's own random draws, recorded (see species.weber_penn for their meaning).
        "scaleV": lambda rng, params: float(rng.uniform(-scale_var, scale_var)),
        "scaleV0": lambda rng, params: float(rng.uniform(1 - radius_var, 1 + radius_var)),
        "leafScaleV": lambda rng, params: float(rng.uniform(1 - leaf_var, 1 + leaf_var)),
        "curveV1": lambda rng, params: rng.uniform(0, cv).tolist(),
        "curveV2": lambda rng, params: rng.uniform(0, cv).tolist(),
        "splitAngleV1": lambda rng, params: rng.uniform(-sv, sv).tolist(),
        "splitAngleV2": lambda rng, params: rng.uniform(-sv, sv).tolist(),
        "rLastAng": lambda rng, params: rng.uniform(0, 360, 4).tolist(),
        "choiceNegPos1": lambda rng, params: int(rng.choice([-1, 1])),
        "choiceNegPos2": lambda rng, params: int(rng.choice([-1, 1])),
        # rSplits2 is left out on purpose: as one threshold for every split decision of the tree, a small value
        # makes every segment split and the tree grows exponentially; without it each decision is drawn from
        # the dictionary's seed, as Sapling does.
    })
    fixed = {k: v for k, v in base.items() if k not in ranges}
    return Preset(name=name, generator="weber_penn", description=description, fixed=fixed, ranges=ranges)


def _presets() -> list[Preset]:
    tsn = dict(fixed_keys=("curve", "downAngle", "splitAngle"))
    return [
        # --- TreeSketchNet's five species (bases from its published test dictionaries)
        make_preset("maple", "TreeSketchNet maple (Acer): forked trunk, broad tend-flame crown, 2 levels", {
            "attractOut": [0, 0.8, 0, 0], "attractUp": [3.5, -1.9, 0, 0], "baseSize": 0.3, "baseSize_s": 0.16,
            "baseSplits": 3, "branchDist": 1.5, "branches": [0, 55, 10, 1], "curve": [0, -15, 0, 0],
            "curveRes": [8, 5, 3, 1], "customShape": [0.5, 1.0, 0.3, 0.5], "downAngle": [0, 26.2, 52.6, 30],
            "downAngleV": [0, 9.7, -6.9, -0.5], "leafDist": "6", "leafDownAngle": 30.0, "leafDownAngleV": -1.0,
            "leafRotate": 137.5, "leafRotateV": -8.4, "leafScale": 0.4, "leafScaleT": 0.1, "leafScaleX": 0.8,
            "leafShape": "rect", "leafangle": -12.0, "leaves": 150, "length": [0.8, 0.6, 0.5, 0.1], "levels": 2,
            "maxBaseSplits": 3, "ratio": 0.015, "ratioPower": 1.2, "rotate": [109.6, 137.5, 137.5, 137.5],
            "rotateV": [-7.4, 0, 0, 0], "scale": 5.0, "segSplits": [0.1, 0.5, 0.2, 0], "shape": "7",
            "shapeS": "10", "splitAngle": [18, 18, 22, 0], "splitBias": 0.55, "splitHeight": 0.6,
            "taperCrown": 0.5, "useOldDownAngle": True}, scale_var=0.8, curve_var=[2, 10, 20, 0],
            split_var=[4, 4, 4, 0], leaf=(0.30, 0.50, 0.12), **tsn),
        make_preset("pine", "TreeSketchNet pine: straight leader, whorled drooping branches, needle cards", {
            "attractUp": [2.0, 0, 0.5, 0.5], "baseSize": 0.068, "baseSize_s": 0.25, "branchDist": 1.6,
            "branches": [0, 36, 7, 10], "curve": [0, -40, -30, 0], "customShape": [0.9, 1.0, 0.2, 0.2],
            "downAngle": [90, 110, 45, 45], "downAngleV": [0, 42, 10, 10], "horzLeaves": False, "leafDist": "3",
            "leafDownAngle": 65.0, "leafDownAngleV": 55.0, "leafRotateV": -10.9, "leafScale": 0.2,
            "leafScaleT": 0.25, "leafScaleX": 0.02, "leafShape": "rect", "leafangle": -10.0, "leaves": 500,
            "length": [1.0, 0.32, 0.75, 0.45], "levels": 3, "nrings": 7, "pruneBase": 0.3, "ratio": 0.02,
            "ratioPower": 1.0, "rotate": [231.2, 137.5, -90, 137.5], "rotateV": [3.9, 0, 0, 0], "scale": 4.0,
            "segSplits": [0, 0.3, 0.4, 0], "shape": "8", "splitAngle": [0, 22, 25, 0], "splitHeight": 0.2},
            scale_var=0.5, curve_var=[6, 10, 15, 0], split_var=[0, 2, 0, 0], whorls=True, leaf=(0.13, 0.30, 0.12),
            bark=(0.30, 0.22, 0.17), **tsn),
        make_preset("bonsai", "TreeSketchNet bonsai: S-curved trunk, four levels of small dense pads", {
            "attractOut": [0, 1, 0, 0], "attractUp": [0.81, 0, 0.21, 0], "baseSize": 0.2, "baseSize_s": 0.0,
            "bevelRes": 2, "branchDist": 1.5, "branches": [0, 15, 15, 10], "curve": [-124.8, 145, 0, -25],
            "curveBack": [124.8, -135, -100, 0], "curveRes": [15, 10, 5, 2], "customShape": [1, 0.85, 0.16, 0.46],
            "downAngle": [0, 41, 0, 0], "downAngleV": [0, 10, 10, 0], "leafDist": "3", "leafDownAngle": 50.0,
            "leafDownAngleV": 0.0, "leafRotateV": -10.3, "leafScale": 0.03, "leafScaleT": 0.1, "leafScaleX": 0.5,
            "leafShape": "rect", "leaves": 20, "length": [1.03, 0.6, 0.4, 0.5], "levels": 4, "minRadius": 0.0,
            "ratio": 0.045, "ratioPower": 1.0, "rotate": [64.8, 121.1, 137.5, 137.5], "rotateV": [-29.3, 0, 0, 0],
            "scale": 1.0, "segSplits": [0, 0, 0.9, 0], "shape": "8", "shapeS": "1", "splitAngle": [0, 19.3, 50, 0],
            "splitBias": 2.0, "splitHeight": 0.0, "taper": [0.65, 1, 1, 1], "taperCrown": 0.3,
            "useParentAngle": False}, scale_var=0.05, curve_var=[2, 5, 12, 0], split_var=[0, 2, 2, 0],
            fixed_keys=("curve", "downAngle", "splitAngle", "scale"), leaf=(0.20, 0.42, 0.15)),
        make_preset("palm", "TreeSketchNet palm: tall leaning stem, crown of long drooping fronds", {
            "attractUp": [8.57, -0.24, 0.5, 0.5], "baseSize": 0.0, "baseSize_s": 0.0, "bevelRes": 2,
            "branchDist": 10.0, "branches": [0, 25, 30, 10], "curve": [68.8, 50, 0, 0],
            "curveBack": [-68.8, 17.9, 0, 0], "customShape": [1, 1, 1, 0.83], "downAngle": [0, 45, 0, 0],
            "downAngleV": [0, 0, 10, 10], "horzLeaves": False, "leafDist": "6", "leafDownAngle": 40.0,
            "leafDownAngleV": 24.3, "leafRotate": 90.0, "leafRotateV": -1.8, "leafScale": 1.31, "leafScaleT": 0.88,
            "leafScaleX": 0.05, "leafShape": "hex", "leafangle": -4.6, "leaves": 200, "length": [0.6, 0.36, 1e-6, 1e-6],
            "levels": 2, "minRadius": 0.0, "nrings": 5, "pruneBase": 0.0, "ratio": 0.02, "ratioPower": 2.0,
            "rotate": [238.5, 65.5, 0, 0], "rotateV": [-6.4, 0, 0, 0], "scale": 14.0, "shape": "8", "shapeS": "2",
            "splitAngle": [7.26, 0, 0, 0], "splitHeight": 0.0, "taper": [0, 1, 1, 1]},
            scale_var=1.0, curve_var=[8, 0, 0, 0], fixed_keys=("curve", "downAngle", "splitAngle", "baseSize"),
            leaf=(0.22, 0.48, 0.16), bark=(0.45, 0.38, 0.28)),
        make_preset("cherry", "TreeSketchNet cherry blossom: wide vase crown, four levels, leaf fans at tips", {
            "attractUp": [0, 0, 0.18, 0], "baseSize": 0.5, "baseSize_s": 0.5, "branchDist": 2.0,
            "branches": [0, 40, 40, 10], "curve": [36.4, -12.2, 0, -20], "curveBack": [5.1, 21.8, 8.4, 0],
            "curveRes": [10, 5, 3, 1], "customShape": [0.8, 1.0, 0.1, 1.0], "downAngle": [0, 50, 45, 30],
            "downAngleV": [0, 6.8, -3.9, 0], "leafDist": "3", "leafDownAngle": -50.0, "leafDownAngleV": 0.0,
            "leafRotate": 280.0, "leafRotateV": 0.0, "leafScale": 0.1, "leafScaleT": 0.1, "leafScaleX": 1.0,
            "leafShape": "rect", "leafangle": 20.0, "leaves": -5, "length": [0.68, 0.6, 0.13, 0.5], "levels": 4,
            "maxBaseSplits": 1, "minRadius": 0.0, "ratio": 0.04, "ratioPower": 1.65, "rootFlare": 1.15,
            "rotate": [283.5, 107.2, 100, 280], "rotateV": [1.2, 0, 0, 0], "scale": 12.0,
            "segSplits": [0.1, 0.5, 0.5, 0.5], "shape": "8", "splitAngle": [20, 35, 40, 60], "splitBias": 1.0,
            "splitHeight": 0.37, "taperCrown": 0.5, "useOldDownAngle": True}, scale_var=1.5,
            curve_var=[2, 15, 22, 0], split_var=[0, 8, 1, 0], leaf=(0.93, 0.70, 0.78), bark=(0.30, 0.20, 0.17),
            fixed_keys=("curve", "downAngle", "splitAngle", "leaves")),
        # --- classic Weber & Penn trees (numbers after the paper and Sapling's presets)
        make_preset("quaking_aspen", "Quaking aspen: slender straight trunk, narrow tend-flame crown", {
            "downAngleV": [0, -50, 10, 10], "scale": 13.0, "ratio": 0.015, "curveRes": [3, 5, 3, 1],
            "curve": [0, -40, -40, 0], "rotate": [140, 140, 140, 77], "length": [1, 0.3, 0.6, 0.45],
            "leafScale": 0.17, "attractUp": [0, 0, 0.5, 0.5], "leaves": 25},
            scale_var=3.0, curve_var=[20, 50, 75, 0], leaf=(0.35, 0.55, 0.15), bark=(0.72, 0.70, 0.62)),
        make_preset("black_oak", "California black oak: low forks, wide spreading hemispherical crown", {
            "downAngleV": [0, -30, 10, 10], "lengthV": [0, 0.1, 0.05, 0], "shape": "2", "splitAngle": [10, 10, 10, 0],
            "baseSize": 0.05, "baseSplits": 2, "scale": 10.0, "ratio": 0.018, "segSplits": [0.4, 0.2, 0.1, 0],
            "ratioPower": 1.3, "length": [1, 0.8, 0.2, 0.4], "attractUp": [0, 0.8, 0.8, 0.8],
            "downAngle": [0, 30, 45, 45], "leafScaleX": 0.66, "curveRes": [8, 10, 3, 1], "rotate": [0, 80, 140, 140],
            "branches": [0, 40, 120, 0], "leaves": 25, "curve": [0, 40, 0, 0], "leafScale": 0.12,
            "curveBack": [0, -70, 0, 0], "splitHeight": 0.3}, scale_var=2.0, curve_var=[90, 150, 30, 0],
            split_var=[0, 10, 10, 0], fork_max=2, leaf=(0.22, 0.38, 0.12), bark=(0.25, 0.22, 0.20)),
        make_preset("black_tupelo", "Black tupelo: tall single trunk, tapered-cylinder crown of many short limbs", {
            "downAngleV": [0, -40, 10, 10], "lengthV": [0, 0.05, 0.1, 0], "shape": "4", "baseSize": 0.2,
            "scale": 23.0, "ratio": 0.015, "ratioPower": 1.3, "length": [1, 0.3, 0.6, 0.4],
            "attractUp": [0, 0.5, 0.5, 0.5], "levels": 4, "downAngle": [90, 60, 30, 45], "leafScaleX": 0.5,
            "curveRes": [10, 10, 10, 1], "rotate": [140, 140, 140, 140], "branches": [0, 50, 25, 12], "leaves": 6,
            "curve": [0, 0, -10, 0], "leafScale": 0.3}, scale_var=5.0, curve_var=[40, 90, 150, 0],
            leaf=(0.20, 0.40, 0.13), bark=(0.33, 0.28, 0.24)),
        make_preset("weeping_willow", "Weeping willow: short forked trunk, long whips hanging to the ground", {
            "downAngleV": [0, 10, 10, 10], "lengthV": [0, 0.1, 0, 0], "shape": "3", "splitAngle": [3, 30, 45, 0],
            "baseSize": 0.05, "baseSplits": 2, "scale": 15.0, "ratio": 0.03, "segSplits": [0.1, 0.1, 0.05, 0],
            "ratioPower": 2.0, "length": [0.8, 0.5, 1.5, 0.1], "rotateV": [0, 30, 30, 0],
            "attractUp": [0, -3, -3, -3], "levels": 3, "downAngle": [0, 20, 30, 20], "leafScaleX": 0.2,
            "curveRes": [8, 10, 10, 1], "rotate": [0, -120, -120, 140], "branches": [0, 25, 10, 300], "leaves": 15,
            "curve": [0, 40, 0, 0], "leafScale": 0.12, "curveBack": [20, 80, 0, 0], "leafShape": "rect",
            "prune": True, "pruneRatio": 1.0, "pruneWidth": 0.4, "pruneWidthPeak": 0.6, "pruneBase": 0.05,
            "splitHeight": 0.4}, scale_var=3.0, curve_var=[40, 60, 0, 0], split_var=[0, 10, 20, 0], fork_max=2,
            leaf=(0.40, 0.55, 0.20), bark=(0.35, 0.30, 0.25), fixed_keys=("attractUp",)),
        make_preset("balsam_fir", "Balsam fir: narrow cone, whorled horizontal branches, dense short needles", {
            "shape": "0", "baseSize": 0.05, "scale": 10.0, "ratio": 0.02, "ratioPower": 1.5,
            "length": [1, 0.3, 0.4, 0.45], "attractUp": [0, -0.3, 0.2, 0.2], "levels": 3,
            "downAngle": [0, 85, 45, 45], "downAngleV": [0, 10, 10, 10], "curveRes": [12, 6, 3, 1],
            "rotate": [140, 137.5, -90, 137.5], "branches": [0, 60, 12, 10], "nrings": 14, "leaves": 120,
            "leafScale": 0.06, "leafScaleX": 0.15, "leafShape": "rect", "curve": [0, -10, 0, 0],
            "leafDownAngle": 60.0, "horzLeaves": False}, scale_var=1.5, curve_var=[5, 15, 20, 0], whorls=True,
            leaf=(0.10, 0.26, 0.12), bark=(0.32, 0.25, 0.20)),
        make_preset("lombardy_poplar", "Lombardy poplar: columnar crown of steep branches hugging the trunk", {
            "shape": "3", "baseSize": 0.1, "scale": 20.0, "ratio": 0.015, "ratioPower": 1.3,
            "length": [1, 0.25, 0.4, 0.45], "attractUp": [0, 1.0, 1.0, 0.5], "levels": 3,
            "downAngle": [0, 25, 30, 45], "downAngleV": [0, 5, 10, 10], "curveRes": [10, 6, 3, 1],
            "rotate": [140, 137.5, 137.5, 137.5], "branches": [0, 70, 25, 10], "leaves": 20, "leafScale": 0.12,
            "curve": [0, 10, 0, 0]}, scale_var=2.0, curve_var=[5, 20, 30, 0], leaf=(0.25, 0.45, 0.12),
            bark=(0.40, 0.36, 0.30)),
        make_preset("sassafras", "Sassafras: crooked trunk, open layered crown of upturned limbs", {
            "shape": "2", "baseSize": 0.2, "scale": 14.0, "ratio": 0.017, "ratioPower": 1.3,
            "length": [1, 0.55, 0.5, 0.4], "attractUp": [0, 1.2, 0.6, 0.5], "levels": 3,
            "downAngle": [0, 80, 40, 45], "downAngleV": [0, 10, 10, 10], "curveRes": [12, 12, 4, 1],
            "rotate": [140, 140, 140, 140], "branches": [0, 18, 24, 10], "segSplits": [0.3, 0.1, 0.1, 0],
            "splitAngle": [12, 20, 20, 0], "leaves": 16, "leafScale": 0.2, "curve": [0, -40, 0, 0],
            "curveBack": [0, 60, 0, 0], "splitHeight": 0.5}, scale_var=2.0, curve_var=[60, 40, 40, 0],
            split_var=[4, 8, 8, 0], leaf=(0.30, 0.50, 0.14), bark=(0.42, 0.31, 0.24)),
        make_preset("silver_birch", "Silver birch: white slender trunk, light crown of arching twigs", {
            "shape": "7", "baseSize": 0.3, "scale": 16.0, "ratio": 0.012, "ratioPower": 1.2,
            "length": [1, 0.35, 0.6, 0.4], "attractUp": [0, 0.3, -0.8, -0.8], "levels": 3,
            "downAngle": [0, 45, 45, 45], "downAngleV": [0, -30, 10, 10], "curveRes": [10, 8, 5, 1],
            "rotate": [140, 137.5, 137.5, 137.5], "branches": [0, 40, 30, 10], "leaves": 18, "leafScale": 0.1,
            "curve": [0, -20, -30, 0]}, scale_var=2.0, curve_var=[10, 40, 60, 0], leaf=(0.38, 0.58, 0.16),
            bark=(0.86, 0.85, 0.80)),
        make_preset("douglas_fir", "Douglas fir: tall conical conifer, drooping-then-rising limbs", {
            "shape": "0", "baseSize": 0.15, "scale": 24.0, "ratio": 0.02, "ratioPower": 1.4,
            "length": [1, 0.28, 0.4, 0.45], "attractUp": [0, 0.4, 0.2, 0.2], "levels": 3,
            "downAngle": [0, 95, 45, 45], "downAngleV": [0, 20, 10, 10], "curveRes": [14, 8, 3, 1],
            "rotate": [140, 137.5, 137.5, 137.5], "branches": [0, 70, 12, 10], "leaves": 60, "leafScale": 0.08,
            "leafScaleX": 0.2, "leafShape": "rect", "curve": [0, -25, 0, 0], "horzLeaves": False},
            scale_var=3.0, curve_var=[5, 20, 20, 0], leaf=(0.12, 0.28, 0.13), bark=(0.30, 0.21, 0.16)),
    ]


PRESETS = _presets()
