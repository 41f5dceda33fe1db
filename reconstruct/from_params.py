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

from ._sketch_arrays import check_height
from .networks import as_image, predictor

__all__ = ["ParamsReconstruction", "from_params", "scaled_to_height"]


@dataclass(frozen=True, eq=False)
class ParamsReconstruction:
    """A Weber-Penn tree from one sketch: the dictionary the network read, the grown skeleton and mesh, and the
    report (`timings` in seconds: "network", "grow_mesh", "total"; `maps`: "input", the network's input)."""

    params: dict
    skeleton: Skeleton
    mesh: TreeMesh
    timings: dict[str, float] = field(default_factory=dict)
    maps: dict[str, np.ndarray] = field(default_factory=dict)


_HEIGHT_TOLERANCE = 0.01  # relative: a second rescale when the first leaves the tree further off (leaves, tips)


def scaled_to_height(params: dict, height: float) -> tuple[dict, Skeleton, TreeMesh]:
    """The dictionary with its tree scale (`scale` + `scaleV`, realized draws) set so the tree grows `height`
    metres tall, and that tree. Weber-Penn lengths are proportional to the tree scale; leaves are not, so a
    second step corrects what the first leaves over _HEIGHT_TOLERANCE."""
    skeleton, mesh = species.rebuild(params)
    for _ in range(2):
        if abs(skeleton.height - height) <= _HEIGHT_TOLERANCE * height:
            break
        tree_scale = params["scale"] + params.get("scaleV", 0.0)
        params = {**params, "scale": tree_scale * height / skeleton.height - params.get("scaleV", 0.0)}
        skeleton, mesh = species.rebuild(params)
    return params, skeleton, mesh


def from_params(sketch, *, models=None, net=None, seed: int = 0, height: float | None = None) -> ParamsReconstruction:
    """Read a Sapling dictionary from `sketch` and grow it.

    sketch : (H, W) grey, (H, W, 3) or (H, W, 4) image, dark strokes on light paper, any size.
    models : a registry URI or folder (its champion), or None for the shipped default; net : a loaded predictor.
    seed   : the dictionary's `seed` (Weber-Penn's split and variation draws), so one sketch can give variants.
    height : metres; the dictionary's scale is set so the tree is this tall (`scaled_to_height`). A sketch is
             drawn at no scale, so without it the size is the network's guess from the tree's species and shape.
    """
    check_height(height, "the network's guess")
    start = time.perf_counter()
    image = as_image(sketch, "sketch")
    net = net or predictor("sketchnet", models)
    params, prepared = net.predict_view(image, seed=int(seed))
    network = time.perf_counter() - start
    if height is None:
        skeleton, mesh = species.rebuild(params)
    else:
        params, skeleton, mesh = scaled_to_height(params, float(height))
    total = time.perf_counter() - start
    return ParamsReconstruction(params, skeleton, mesh, {"network": network, "grow_mesh": total - network,
                                                         "total": total}, {"input": prepared.image[0]})
