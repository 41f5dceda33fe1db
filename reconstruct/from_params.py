"""Parameters from one sketch (seed 004, TreeSketchNet): a drawing to a Sapling dictionary to a Weber-Penn tree.

The TreeSketchNet predictor (`trainers.models.load("sketchnet")`: the shipped default or a registry's champion)
reads a drawing of any size (black strokes on white; `trainers.preprocess` normalises it as the training sketches
were) and decodes a dictionary `species.grow` accepts, with the species it read and the decode seed. The tree is
`species.rebuild(params)`, the very call `farm tree --params` makes, so the written dictionary rebuilds the same
bytes; the species read back chooses the bark and leaf textures as any preset's dictionary does.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

import species
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh

from .networks import as_image, predictor

__all__ = ["ParamsReconstruction", "from_params"]


@dataclass(frozen=True, eq=False)
class ParamsReconstruction:
    """A Weber-Penn tree from one sketch: the dictionary the network read, the grown skeleton and mesh, and the
    report (`timings` in seconds: "network", "grow_mesh", "total"; `maps`: "input", the network's input)."""

    params: dict
    skeleton: Skeleton
    mesh: TreeMesh
    timings: dict[str, float] = field(default_factory=dict)
    maps: dict[str, np.ndarray] = field(default_factory=dict)


def from_params(sketch, *, models=None, net=None, seed: int = 0) -> ParamsReconstruction:
    """Read a Sapling dictionary from `sketch` and grow it.

    sketch : (H, W) grey, (H, W, 3) or (H, W, 4) image, dark strokes on light paper, any size.
    models : a registry URI or folder (its champion), or None for the shipped default; net : a loaded predictor.
    seed   : the dictionary's `seed` (Weber-Penn's split and variation draws), so one sketch can give variants.
    """
    start = time.perf_counter()
    image = as_image(sketch, "sketch")
    net = net or predictor("sketchnet", models)
    params, prepared = net.predict_view(image, seed=int(seed))
    network = time.perf_counter() - start
    skeleton, mesh = species.rebuild(params)
    total = time.perf_counter() - start
    return ParamsReconstruction(params, skeleton, mesh, {"network": network, "grow_mesh": total - network,
                                                         "total": total}, {"input": prepared.image[0]})
