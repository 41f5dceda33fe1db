"""Physically based texture sets for library assets: tileable bark (base colour, normal, roughness) made
procedurally per species, and per-season leaf atlases (a single leaf and a leaf clump, with alpha).

In: a species name, colours, a texture size. Out: uint8 images (sRGB colour, linear normal/roughness).
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import ParameterError
from ..meshing.textures import (BARK_TEXTURE_SEED, bark_colour, fissure_depth, leaf_texture, linear_to_srgb,
                                periodic_noise)

__all__ = ["BarkMaps", "bark_maps", "leaf_atlas", "SEASON_LEAF_COLOURS", "SEASONS", "season_leaf_colour"]

SEASONS = ("spring", "summer", "autumn", "bare")
# Leaf colour of each season as a multiple of / replacement for the species' summer leaf colour (linear RGB).
SEASON_LEAF_COLOURS = {"spring": (0.42, 0.62, 0.16), "autumn": (0.62, 0.22, 0.04)}


def season_leaf_colour(season: str, summer_colour) -> tuple[float, float, float]:
    """Linear RGB leaf colour of a season: the species' own colour in summer, fixed hues in spring/autumn."""
    if season not in SEASONS or season == "bare":
        raise ParameterError("season", season, f"one of {', '.join(s for s in SEASONS if s != 'bare')}")
    if season == "summer":
        return tuple(float(c) for c in summer_colour)
    mixed = 0.6 * np.asarray(SEASON_LEAF_COLOURS[season]) + 0.4 * np.asarray(summer_colour, float)
    return tuple(float(c) for c in np.clip(mixed, 0.0, 1.0))


@dataclass(frozen=True)
class BarkMaps:
    """base_color (S, S/2... , 3) uint8 sRGB; normal (H, W, 3) uint8 tangent space (+x along u, +y along v);
    roughness_metallic (H, W, 3) uint8 in glTF's packing (G roughness, B metallic 0, R unused 255)."""

    base_color: np.ndarray
    normal: np.ndarray
    roughness_metallic: np.ndarray


def bark_maps(species_name: str, color, size: int = 256) -> BarkMaps:
    """Tileable bark maps for a species (see `_bark_maps`); cached per species, colour and size, read-only."""
    return _bark_maps(species_name, tuple(float(c) for c in color), int(size))


@lru_cache(maxsize=32)
def _bark_maps(species_name: str, color: tuple[float, float, float], size: int) -> BarkMaps:
    """Tileable bark maps (height `size`, width size / 2, as the bark UVs expect) for a species.

    The species name picks the look (fissure depth and spacing, plate size) from a fixed seed plus the name's
    CRC-32, so every tree of a species shares one texture set and the same name gives the same bytes.
    """
    if not 16 <= size <= 4096 or size % 2:
        raise ParameterError("texture_size", size, "an even integer in [16, 4096]")
    rng = np.random.default_rng([BARK_TEXTURE_SEED, zlib.crc32(species_name.encode())])
    shape = (size, size // 2)
    scale = size / 256.0
    # The look's numbers are drawn between the noise fields, in this order: the same name, the same bytes.
    fissure_spacing = rng.uniform(2.0, 5.0) * scale
    streaks = periodic_noise(rng, shape, sigma_rows=rng.uniform(10, 24) * scale, sigma_cols=fissure_spacing)
    fissure = fissure_depth(streaks, rng.uniform(0.3, 0.6))
    plates = periodic_noise(rng, shape, sigma_rows=rng.uniform(4, 9) * scale, sigma_cols=rng.uniform(3, 6) * scale)
    grain = periodic_noise(rng, shape, sigma_rows=1.2 * scale, sigma_cols=0.6 * scale)
    height = 1.0 - fissure + 0.25 * plates + 0.05 * grain  # relative bark relief, 1 on the plates
    base = bark_colour(color, fissure, plates, grain)
    strength = rng.uniform(2.0, 4.0) / scale
    # Central differences with wrap-around, so the normal map tiles like the height field.
    du = 0.5 * (np.roll(height, -1, axis=1) - np.roll(height, 1, axis=1))
    dv = 0.5 * (np.roll(height, 1, axis=0) - np.roll(height, -1, axis=0))  # image rows run down, v up
    normal = np.stack([-strength * du, -strength * dv, np.ones_like(height)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal8 = np.round((normal + 1.0) * 127.5).astype(np.uint8)
    roughness = np.clip(0.75 + 0.2 * fissure - 0.05 * plates, 0.0, 1.0)
    packed = np.stack([np.full_like(roughness, 1.0), roughness, np.zeros_like(roughness)], axis=-1)
    maps = BarkMaps(base, normal8, np.round(packed * 255).astype(np.uint8))
    for image in (maps.base_color, maps.normal, maps.roughness_metallic):
        image.setflags(write=False)
    return maps


# The cluster tile: leaves on rings (count, radius and scale as fractions of the tile) around a shaded core of
# this radius, tips outward, so a merged card reads as a dense, round clump whose outline is nearly convex.
_CLUMP_RINGS = ((14, 0.22, 0.29), (8, 0.11, 0.29), (1, 0.0, 0.29))
_CLUMP_CORE = 0.26


@lru_cache(maxsize=32)
def _leaf_atlas(color: tuple[float, float, float], size: int) -> np.ndarray:
    import cv2

    leaf = leaf_texture(color, size)
    core = leaf.copy()
    pixel = (np.arange(size) + 0.5) / size - 0.5
    disc = np.hypot(pixel[None, :], pixel[:, None]) <= _CLUMP_CORE
    core[...] = 0
    core[disc, :3] = np.round(linear_to_srgb(0.7 * np.asarray(color)) * 255).astype(np.uint8)
    core[disc, 3] = 255
    clump = core
    stem = (size / 2 - 0.5, size * 0.95)
    for count, radius, shrink in _CLUMP_RINGS:
        for k in range(count):
            angle = 360.0 * k / count + 11.0 * radius * count  # rings staggered
            matrix = cv2.getRotationMatrix2D(stem, angle, shrink)
            direction = np.radians(angle)
            target = np.array([size / 2, size / 2]) + radius * size * np.array([-np.sin(direction), -np.cos(direction)])
            matrix[:, 2] += target - np.asarray(stem)
            turned = cv2.warpAffine(leaf, matrix, (size, size), flags=cv2.INTER_LINEAR, borderValue=(0, 0, 0, 0))
            over = turned[..., 3] >= 128
            clump[over] = turned[over]
    clump.setflags(write=False)
    out = np.concatenate([leaf, clump], axis=1)
    out.setflags(write=False)
    return out


def leaf_atlas(color, size: int = 128) -> np.ndarray:
    """(size, 2 size, 4) uint8 sRGB + alpha, read-only (cached per colour and size): left tile one leaf (LOD0
    cards, stem at the bottom), right tile a round clump of many leaves around a shaded core (the merged
    cluster cards of coarser levels, centred on the tile)."""
    if not 16 <= size <= 4096:
        raise ParameterError("texture_size", size, "an integer in [16, 4096]")
    return _leaf_atlas(tuple(float(c) for c in color), int(size))
