"""Parameters from one sketch (seed 004, TreeSketchNet): a drawing to a Sapling dictionary to a Weber-Penn tree.

The TreeSketchNet predictor (`trainers.models.load("sketchnet")`: the shipped default or a registry's champion)
reads a drawing of any size (black strokes on white; `trainers.preprocess` normalises it as the training sketches
were) and decodes a dictionary `species.grow` accepts, with the species it read and the decode seed. The tree is
`species.rebuild(params)`, the very call `farm tree --params` makes, so the written dictionary rebuilds the same
bytes; the species read back chooses the bark and leaf textures as any preset's dictionary does.
"""
from __future__ import annotations

import species
from species.skeleton import Skeleton
from species.timing import StageTimer
from species.tree_mesh import TreeMesh

from ._sketch_arrays import check_height
from .networks import as_image, predictor
from .result import Reconstruction

__all__ = ["from_params", "scaled_to_height"]


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


def from_params(sketch, *, models=None, net=None, seed: int = 0, height: float | None = None) -> Reconstruction:
    """Read a Sapling dictionary from `sketch` and grow it: the `Reconstruction` (method "params") of the dictionary
    the network read, its skeleton and mesh; timings "network", "grow_mesh", "total"; maps "input" (the network's
    input) and "species" (the species the network read, its confidence on [0, 1]: the softmax probability of that
    species among those training held).

    sketch : (H, W) grey, (H, W, 3) or (H, W, 4) image, dark strokes on light paper, any size.
    models : a registry URI or folder (its champion), or None for the shipped default; net : a loaded predictor.
    seed   : the dictionary's `seed` (Weber-Penn's split and variation draws), so one sketch can give variants.
    height : metres; the dictionary's scale is set so the tree is this tall (`scaled_to_height`). A sketch is
             drawn at no scale, so without it the size is the network's guess from the tree's species and shape.
    """
    check_height(height, "the network's guess")
    timer = StageTimer()
    image = as_image(sketch, "sketch")
    net = net or predictor("sketchnet", models)
    outputs, prepared = net.outputs_view(image)
    params = net.codec.decode_arrays(dict(outputs), seed=int(seed))[0]
    confidence = float(net.codec.species_confidence(dict(outputs))[0])
    timer.lap("network")
    if height is None:
        skeleton, mesh = species.rebuild(params)
    else:
        params, skeleton, mesh = scaled_to_height(params, float(height))
    timer.lap("grow_mesh")
    timings = {**timer.seconds, "total": sum(timer.seconds.values())}
    return Reconstruction("params", skeleton, mesh, params, timings,
                          {"input": prepared.image[0], "species": (params["species"], confidence)})
