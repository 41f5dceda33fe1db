"""treefarm's ground floor: what a tree is.

Public API: `list_presets()`, `sample(preset, rng) -> dict`, `grow(params, rng) -> Skeleton`,
`build_mesh(skeleton, params) -> TreeMesh`, and the types `Skeleton`, `TreeMesh`, `MeshPart`.
Nothing here knows about Ray, Parquet, torch or a renderer.
"""
from __future__ import annotations

import importlib

from .errors import ParameterError, TreefarmError
from .growth import GENERATORS, generator_of, grow, rng_for
from .presets import Preset, PresetError, get_preset, list_presets, register_presets, sample
from .skeleton import Skeleton, SkeletonError
from .tree_mesh import MeshPart, TreeMesh

__all__ = [
    "list_presets", "get_preset", "sample", "grow", "build_mesh", "rng_for", "generator_of",
    "Skeleton", "TreeMesh", "MeshPart", "Preset",
    "TreefarmError", "ParameterError", "PresetError", "SkeletonError", "GENERATORS",
]

# Each generator's presets live in its own module and load on first use.
for _module in ("species.weber_penn_presets", "species.lsystem_presets", "species.colonization_presets"):
    register_presets(lambda _m=_module: importlib.import_module(_m).PRESETS)


def build_mesh(skeleton: Skeleton, params: dict | None = None) -> TreeMesh:
    """Mesh a skeleton: bark tubes and leaf cards (see `species.mesh`)."""
    from .mesh import build_mesh as _build_mesh

    return _build_mesh(skeleton, params)
