"""treefarm's ground floor: what a tree is.

Public API: `list_presets()`, `sample(preset, rng) -> dict`, `grow(params, rng) -> Skeleton`,
`build_mesh(skeleton, params) -> TreeMesh`, `rebuild(params) -> (Skeleton, TreeMesh)` (a dictionary's own tree),
`sapling_preset(path) -> dict` (a preset file of Blender's Sapling add-on, to grow),
and the types `Skeleton`, `TreeMesh`, `MeshPart`. Subpackages: `weber_penn`, `colonization`, `lsystem` (the
generators and their presets), `meshing`, `geometry`, `studio` (levels of detail, wind, textures for assets).
Nothing here knows about Ray, Parquet, torch or a renderer.
"""
from __future__ import annotations

import importlib

from .errors import ParameterError, TreefarmError, TreeTooLargeError
from .growth import GENERATORS, Generator, generator_of, grow, rebuild, rng_for
from .meshing import build_mesh
from .presets import Preset, PresetError, get_preset, list_presets, register_presets, sample
from .skeleton import Skeleton, SkeletonError
from .tree_mesh import MeshPart, TreeMesh

__all__ = [
    "list_presets", "get_preset", "sample", "sapling_preset", "grow", "build_mesh", "rebuild", "rng_for",
    "generator_of",
    "Skeleton", "TreeMesh", "MeshPart", "Preset",
    "TreefarmError", "ParameterError", "PresetError", "SkeletonError", "TreeTooLargeError", "GENERATORS",
    "Generator",
]


def sapling_preset(path) -> dict:
    """The dictionary of a Sapling preset file (.py as Blender's add-on saves it, or .json), as the add-on loads
    it, with `draws: ranges`: `species.grow` draws its variation ranges as Sapling does."""
    # Imported here: the weber_penn package loads on first use, so `import species` (the farm CLI's start-up) stays
    # cheap.
    from .weber_penn.sapling_preset import read_sapling_preset

    return read_sapling_preset(path)


# Each generator's presets live in its own module and load on first use.
for _generator in GENERATORS.values():
    register_presets(lambda _m=_generator.presets: importlib.import_module(_m).PRESETS)
