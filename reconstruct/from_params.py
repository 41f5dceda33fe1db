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
from .fit_budget import DEFAULT_FIT_EVALS, check_fit_evals
from .fitting import FIT_SIZE, drawing_outline, fit_params, renderer_at
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


def from_params(sketch, *, models=None, net=None, seed: int = 0, height: float | None = None,
                fit_evals: int = DEFAULT_FIT_EVALS, renderer=None) -> Reconstruction:
    """Read a Sapling dictionary from `sketch`, fit it to the drawing and grow it: the `Reconstruction` (method
    "params") of the dictionary, its skeleton and mesh; timings "network", "fit" (with fitting), "grow_mesh",
    "total"; maps "input" (the network's input), "species" (the species grown, its confidence on [0, 1]: the
    network's softmax probability of that species among those training held) and, with fitting, "fit" (a
    `reconstruct.fitting.FitRecord`: the outlines and scores of the first guess and the fit, the species tried).

    sketch : (H, W) grey, (H, W, 3) or (H, W, 4) image, dark strokes on light paper, any size.
    models : a registry URI or folder (its champion), or None for the shipped default; net : a loaded predictor.
    seed   : the dictionary's `seed` (Weber-Penn's split and variation draws), so one sketch can give variants.
    height : metres; the dictionary's scale is set so the tree is this tall (`scaled_to_height`). A sketch is
             drawn at no scale, so without it the size is the network's guess from the tree's species and shape.
    fit_evals : candidate trees the fit may grow and redraw (`reconstruct.fitting.fit_params`); 0 grows the
             network's guess as it is.
    renderer : a `renderers.ViewRenderer` to redraw candidates with (one is made when fitting without it).
    """
    check_height(height, "the network's guess")
    fit_evals = check_fit_evals(fit_evals)
    timer = StageTimer()
    image = as_image(sketch, "sketch")
    net = net or predictor("sketchnet", models)
    outputs, prepared = net.outputs_view(image)
    params = net.codec.decode_arrays(dict(outputs), seed=int(seed))[0]
    confidence = float(net.codec.species_confidence(dict(outputs))[0])
    timer.lap("network")
    maps, grown = {"input": prepared.image[0]}, None
    if fit_evals:
        fit = _fitted(net.codec, dict(outputs), image, fit_evals, int(seed), renderer)
        params, maps["fit"], grown = fit.params, fit.record, fit.tree
        confidence = fit.record.species_scores[params["species"]][1]
        timer.lap("fit")
    if height is None and grown is not None:
        skeleton, mesh = grown  # the fit grew this very dictionary: `species.rebuild` gives the same bytes
    elif height is None:
        skeleton, mesh = species.rebuild(params)
    else:
        params, skeleton, mesh = scaled_to_height(params, float(height))
    timer.lap("grow_mesh")
    timings = {**timer.seconds, "total": sum(timer.seconds.values())}
    return Reconstruction("params", skeleton, mesh, params, timings,
                          {**maps, "species": (params["species"], confidence)})


def _fitted(codec, outputs: dict, image, evals: int, seed: int, renderer):
    """`fit_params` on the drawing's outline, with `renderer` (or a new one) at the fit's size."""
    with renderer_at(renderer, FIT_SIZE) as drawing:
        return fit_params(codec, outputs, drawing_outline(image), evals, seed, drawing)
