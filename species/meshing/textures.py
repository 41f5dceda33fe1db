"""Small procedural textures for exported trees: tileable bark with vertical fissures, a leaf with alpha.

In: a base colour (linear RGB). Out: uint8 sRGB images and their deterministic PNG encodings (`png.png_bytes`).
The bark's noise fields and colour formula are public: the studio's PBR bark maps (`species.studio.pbr_textures`)
draw their own fields per species and colour them with the same formula.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..errors import ParameterError
from .png import png_bytes

__all__ = ["bark_texture", "leaf_texture", "bark_png", "leaf_png", "linear_to_srgb", "periodic_noise",
           "fissure_depth", "bark_colour", "BARK_TEXTURE_SEED"]

# Textures are assets, not samples: every tree shares one noise field, drawn from this fixed seed.
BARK_TEXTURE_SEED = 20260101


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (glTF colour textures are sRGB-encoded). Values in [0, 1] both sides."""
    linear = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def _to_uint8(values: np.ndarray) -> np.ndarray:
    return np.round(np.clip(values, 0.0, 1.0) * 255.0).astype(np.uint8)


def _check_colour(color) -> np.ndarray:
    rgb = np.asarray(color, np.float64)
    if rgb.shape != (3,) or not np.all((rgb >= 0) & (rgb <= 1)):
        raise ParameterError("color", color, "three numbers in [0, 1] (linear RGB)")
    return rgb


def periodic_noise(rng: np.random.Generator, shape: tuple[int, int], sigma_rows: float,
                   sigma_cols: float) -> np.ndarray:
    """(H, W) float64 Gaussian-filtered white noise, unit variance, periodic in both axes (FFT filter).

    sigma_rows, sigma_cols : filter widths in pixels along rows (vertical) and columns (horizontal).
    """
    white = rng.standard_normal(shape)
    freq_rows = np.fft.fftfreq(shape[0])[:, None]
    freq_cols = np.fft.rfftfreq(shape[1])[None, :]
    gain = np.exp(-2 * np.pi ** 2 * ((freq_rows * sigma_rows) ** 2 + (freq_cols * sigma_cols) ** 2))
    field = np.fft.irfft2(np.fft.rfft2(white) * gain, s=shape)
    return (field - field.mean()) / max(field.std(), 1e-12)


def bark_texture(color, rng: np.random.Generator, height: int = 256, width: int = 128) -> np.ndarray:
    """(height, width, 3) uint8 sRGB bark: ridges around `color` split by dark vertical fissures.

    color : (3,) float, linear RGB in [0, 1]. Tiles seamlessly in both directions (u around the branch,
    v along it), because the noise is filtered on a torus.
    """
    _check_colour(color)
    # Fissures: zero crossings of noise stretched along v, so cracks run along the branch.
    streaks = periodic_noise(rng, (height, width), sigma_rows=16.0, sigma_cols=3.0)
    fissure = fissure_depth(streaks, 0.45)
    plates = periodic_noise(rng, (height, width), sigma_rows=6.0, sigma_cols=4.0)
    grain = periodic_noise(rng, (height, width), sigma_rows=1.2, sigma_cols=0.6)
    return bark_colour(color, fissure, plates, grain)


def fissure_depth(streaks: np.ndarray, width: float) -> np.ndarray:
    """(H, W) float64 in (0, 1]: 1 on the zero crossings of `streaks` (H, W) unit-variance noise, where the bark
    cracks, falling off within about `width` standard deviations of them."""
    return np.exp(-(streaks / width) ** 2)


def bark_colour(color, fissure: np.ndarray, plates: np.ndarray, grain: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 sRGB bark: `color` (3,) linear RGB in [0, 1] shaded by the relief, darkest in the
    fissures (`fissure_depth`, (H, W)), lighter on raised plates and grain ((H, W) unit-variance noise)."""
    rgb = _check_colour(color)
    shade = 1.05 - 0.75 * fissure + 0.15 * plates + 0.08 * grain
    return _to_uint8(linear_to_srgb(rgb[None, None, :] * np.clip(shade, 0.0, 1.6)[..., None]))


def leaf_texture(color, size: int = 128) -> np.ndarray:
    """(size, size, 4) uint8 sRGB + alpha: an ovate leaf with a midrib and side veins, alpha 0 outside.

    color : (3,) float, linear RGB in [0, 1]. The stem is at the bottom row (texture v = 0 in OBJ
    convention) and the tip at the top, matching leaf cards whose v runs from the stem along the length.
    """
    rgb = _check_colour(color)
    pixel = (np.arange(size) + 0.5) / size
    u = pixel[None, :]                     # across the card, 0..1
    v = 1.0 - pixel[:, None]               # along the card from the stem (bottom row) to the tip
    across = np.abs(u - 0.5)
    blade = np.clip((v - 0.1) / 0.88, 0.0, 1.0)  # 0 at the blade's base, 1 at its tip
    half_width = 0.46 * np.sin(np.pi * blade) ** 0.75 * (1.0 - 0.35 * blade)
    px = 1.0 / size
    inside_blade = np.clip((half_width - across) / (1.5 * px) + 0.5, 0.0, 1.0)
    inside_blade *= (v > 0.1) & (v < 0.98)
    stalk = np.clip((0.015 - across) / px + 0.5, 0.0, 1.0) * (v > 0.01) * (v <= 0.1)
    alpha = np.maximum(inside_blade, stalk)
    midrib = np.clip(1.0 - across / (1.2 * px), 0.0, 1.0)
    vein_phase = (v - 1.1 * across) * 9.0
    veins = np.clip(1.0 - np.abs(vein_phase - np.round(vein_phase)) / 0.06, 0.0, 1.0) * (across < half_width * 0.85)
    shade = 0.85 + 0.3 * blade - 0.25 * (across / 0.46) - 0.25 * np.maximum(midrib, veins)
    shade = np.where(stalk > inside_blade, 0.7, shade)
    colour = linear_to_srgb(rgb[None, None, :] * np.clip(shade, 0.0, 1.5)[..., None])
    return np.concatenate([_to_uint8(colour), _to_uint8(alpha)[..., None]], axis=-1)


@lru_cache(maxsize=64)
def _bark_png(color: tuple[float, float, float], compress_level: int) -> bytes:
    return png_bytes(bark_texture(color, np.random.default_rng(BARK_TEXTURE_SEED)), compress_level)


@lru_cache(maxsize=64)
def _leaf_png(color: tuple[float, float, float], compress_level: int) -> bytes:
    return png_bytes(leaf_texture(color), compress_level)


def bark_png(color, compress_level: int = 9) -> bytes:
    """PNG bytes of `bark_texture(color)` with the fixed texture seed at zlib level `compress_level` (cached per
    colour and level)."""
    return _bark_png(tuple(float(c) for c in _check_colour(color)), compress_level)


def leaf_png(color, compress_level: int = 9) -> bytes:
    """PNG bytes of `leaf_texture(color)` at zlib level `compress_level` (cached per colour and level)."""
    return _leaf_png(tuple(float(c) for c in _check_colour(color)), compress_level)
