"""Weber-Penn shape ratios and automatic taper, vectorized (Sapling's numbering of the shapes).

`shape_ratio(shape, ratio)` gives the length factor of a branch at relative position `ratio` (0 = top).
"""
from __future__ import annotations

import numpy as np

__all__ = ["shape_ratio", "auto_taper", "SHAPE_NAMES"]

SHAPE_NAMES = {0: "conical", 1: "spherical", 2: "hemispherical", 3: "cylindrical", 4: "tapered cylindrical",
               5: "flame", 6: "inverse conical", 7: "tend flame", 8: "custom", 9: "envelope", 10: "inverse tend flame"}


def shape_ratio(shape: int, ratio, custom=None, peak: float = 0.0, power_high: float = 0.0,
                power_low: float = 0.0) -> np.ndarray:
    """Length factor per position; `ratio` (N,) in [0, 1]. Shape 8 needs `custom` (4,), shape 9 the envelope."""
    r = np.asarray(ratio, np.float64)
    if shape == 0:
        return 0.05 + 0.95 * r
    if shape == 1:
        return 0.2 + 0.8 * np.sin(np.pi * r)
    if shape == 2:
        return 0.2 + 0.8 * np.sin(0.5 * np.pi * r)
    if shape == 3:
        return np.ones_like(r)
    if shape == 4:
        return 0.5 + 0.5 * r
    if shape == 5:
        return np.where(r <= 0.7, 0.05 + 0.95 * r / 0.7, 0.05 + 0.95 * (1.0 - r) / 0.3)
    if shape == 6:
        return 1.0 - 0.8 * r
    if shape == 7:
        return np.where(r <= 0.7, 0.5 + 0.5 * r / 0.7, 0.5 + 0.5 * (1.0 - r) / 0.3)
    if shape == 8:
        c = np.asarray(custom, np.float64)
        top = 1.0 - r  # the custom profile runs from the base (0) to the top (1)
        upper = (top - c[2]) / max(1.0 - c[2], 1e-12)
        lower = top / max(c[2], 1e-12)
        value = np.where(top >= c[2], upper * upper * (c[3] - c[1]) + c[1],
                         (1 - (1 - lower) ** 2) * (c[1] - c[0]) + c[0])
        return np.where(top == 1.0, c[3], value)
    if shape == 9:
        inside = (r > 0) & (r < 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            rising = (r / max(1 - peak, 1e-12)) ** power_high
            falling = ((1 - r) / max(peak, 1e-12)) ** power_low
        return np.where(inside, np.where(r < 1 - peak, rising, falling), 0.0)
    if shape == 10:
        return 0.5 + 0.5 * (1 - r)
    raise ValueError(f"shape {shape} is not a Weber-Penn shape id (0..10)")


def auto_taper(length, taper, shape: int, shape_s: int, levels: int, custom) -> list[float]:
    """Sapling's automatic taper: scale each level's taper so radii flow smoothly into the next level."""
    lengths = np.asarray(length, np.float64)
    shapes = [1.0, float(shape_ratio(shape, 0.0, custom)), float(shape_ratio(shape_s, 0.0)),
              float(shape_ratio(shape_s, 0.0))]
    scaled = lengths * np.asarray(shapes)
    products = np.cumprod(scaled)
    remaining = np.array([products[i:levels].sum() for i in range(4)])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(remaining > 0, products / np.where(remaining > 0, remaining, 1), 1.0)
    return (ratio * np.asarray(taper, np.float64)).tolist()
