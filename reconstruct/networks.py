"""The networks' side of reconstruction: drawings through the trained predictors into maps of one frame.

Each network crops its input to its own drawing (`trainers.preprocess`), so the silhouette network's depth maps
and the trunk network's are of two different windows of the page. `sketch_maps` runs both and resamples the trunk
depth and the colour strokes into the silhouette's window, which becomes the reconstruction's view: an
orthographic front camera (`drawing_camera`) of `size` px; the metric scale comes later, from the tree height.

Models: `models=None` loads the defaults shipped in `models/`; a registry URI or folder loads its champions
(`trainers.models.load`). `SPECIES_TO_COLONIZATION` maps the species TreeSketchNet reads from a drawing to the
colonization preset the depth-guided growth uses (`--species auto`).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from renderers.camera import Camera, orthographic_camera
from renderers.sketch import edges_of_grey
from species.errors import TreefarmError
from trainers.preprocess import Crop, apply_crop

__all__ = ["SketchMaps", "sketch_maps", "drawing_camera", "photo_edges", "predictor", "SPECIES_TO_COLONIZATION",
           "InputImageError", "colonization_species", "as_image"]

# TreeSketchNet's species (the Weber-Penn presets) -> the colonization preset of the nearest crown habit.
SPECIES_TO_COLONIZATION = {
    "balsam_fir": "sc_fir", "black_oak": "sc_broad_oak", "black_tupelo": "sc_dense_beech",
    "bonsai": "sc_dome_shrub", "cherry": "sc_open_fruit_tree", "douglas_fir": "sc_spruce",
    "lombardy_poplar": "sc_columnar_poplar", "maple": "sc_round_maple", "palm": "sc_umbrella_pine",
    "pine": "sc_shadow_conifer", "quaking_aspen": "sc_birch_oval", "sassafras": "sc_shadow_oak",
    "silver_birch": "sc_birch_oval", "weeping_willow": "sc_weeping_willow",
}


class InputImageError(TreefarmError):
    """An input image the reconstruction cannot use: not an image array, wrong channels, pages of two sizes."""


def as_image(value, name: str, channels: tuple[int, ...] = (1, 3, 4)) -> np.ndarray:
    """`value` as an (H, W) or (H, W, C) array with C in `channels` (1 = a plain (H, W) grey image)."""
    array = np.asarray(value)
    if array.dtype == object or not (np.issubdtype(array.dtype, np.number) or array.dtype == bool):
        raise InputImageError(f"{name} is not an image (dtype {array.dtype}): allowed an (H, W) or (H, W, C) "
                              "array of numbers")
    if array.ndim == 2 and 1 in channels:
        return array
    if array.ndim == 3 and array.shape[2] in channels:
        return array
    allowed = " or ".join(["(H, W)"] * (1 in channels) + [f"(H, W, {c})" for c in channels if c != 1])
    raise InputImageError(f"{name} has shape {array.shape}: allowed {allowed}")


def predictor(task: str, models=None):
    """The trained predictor of `task` (`trainers.models.load`: shipped default or a registry's champion)."""
    from trainers.models import load  # here: trainers.models imports torch, which a drawing's arrays do not need

    return load(task, models)


def colonization_species(sketchnet_species: str) -> str:
    """The colonization preset for a species TreeSketchNet read (SPECIES_TO_COLONIZATION)."""
    if sketchnet_species not in SPECIES_TO_COLONIZATION:
        raise InputImageError(f"species {sketchnet_species!r} has no colonization preset: allowed "
                              f"{', '.join(sorted(SPECIES_TO_COLONIZATION))}")
    return SPECIES_TO_COLONIZATION[sketchnet_species]


def photo_edges(photo) -> np.ndarray:
    """A photo's silhouette sketch: seed 000's blurred Canny edges (`renderers.sketch.edges_of_grey`) of its grey
    image, black on white (H, W) uint8."""
    image = as_image(photo, "photo", (1, 3, 4))
    if image.dtype != np.uint8:
        scale = 255.0 if np.issubdtype(image.dtype, np.floating) and float(np.nanmax(image)) <= 1.0 else 1.0
        image = np.clip(np.nan_to_num(image.astype(np.float64) * scale), 0, 255).astype(np.uint8)
    if image.ndim == 3:
        image = cv2.cvtColor(image[..., :3], cv2.COLOR_RGB2GRAY)
    return edges_of_grey(image)


def drawing_camera(size: int) -> Camera:
    """The view a drawing is reconstructed in: orthographic, looking along +Y at a 2 x 2 x 2 box standing on the
    origin (the tree's scale is set later from its height), `size` px square."""
    box = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (0.0, 2.0)])
    return orthographic_camera(box, 0.0, 0.0, int(size), name="drawing")


@dataclass(frozen=True)
class SketchMaps:
    """Both depth networks' outputs of one drawing in the silhouette's window.

    silhouette : (S, S, 3) float32 front depth01, gap, mask.  trunk_depth : (S, S) float32, 1 = no stroke.
    strokes    : (S, S, 3) uint8 the colour strokes cut to the same window.  camera : `drawing_camera(S)`.
    crop       : the window on the source page (source pixels).
    sketch_input : (1, S, S) float32 the silhouette network's input (ink 1 on 0).
    """

    silhouette: np.ndarray
    trunk_depth: np.ndarray
    strokes: np.ndarray
    camera: Camera
    crop: Crop
    sketch_input: np.ndarray


def _into_window(image: np.ndarray, own: Crop, window: Crop, size: int, fill, interpolation: int) -> np.ndarray:
    """A network output over its own crop `own` (size px) resampled onto another crop `window` of the page."""
    k = size / own.side
    return apply_crop(image, Crop((window.x0 - own.x0) * k, (window.y0 - own.y0) * k, window.side * k), size, fill,
                      interpolation)


def sketch_maps(sketch, strokes, *, models=None, silhouette_net=None, trunk_net=None) -> SketchMaps:
    """Run the silhouette network on `sketch` (black edges on white, any size) and the trunk network on `strokes`
    (colour strokes on white, drawn on the same page: the same size), and bring both into the sketch's window."""
    sketch = as_image(sketch, "sketch", (1, 3, 4))
    strokes = as_image(strokes, "strokes", (3, 4))
    if sketch.shape[:2] != strokes.shape[:2]:
        raise InputImageError(f"the sketch ({sketch.shape[1]}x{sketch.shape[0]} px) and the strokes "
                              f"({strokes.shape[1]}x{strokes.shape[0]} px) must be drawn on one page: allowed two "
                              "images of one size")
    silhouette_net = silhouette_net or predictor("pix2pix-silhouette", models)
    trunk_net = trunk_net or predictor("pix2pix-trunk", models)
    size = silhouette_net.input_size
    if trunk_net.input_size != size:
        raise InputImageError(f"the trunk network's input size ({trunk_net.input_size} px) differs from the "
                              f"silhouette network's ({size} px): allowed models of one size")
    silhouette, sketch_input = silhouette_net.predict_view(sketch)
    trunk, trunk_input = trunk_net.predict_view(strokes)
    window = sketch_input.crop
    trunk = _into_window(np.asarray(trunk[0], np.float32), trunk_input.crop, window, size, 1.0, cv2.INTER_NEAREST)
    rgb = strokes[..., :3] if strokes.dtype == np.uint8 else np.clip(strokes[..., :3] * 255.0, 0, 255).astype(np.uint8)
    cut = apply_crop(rgb, window, size, 255, cv2.INTER_LINEAR)
    maps = np.moveaxis(np.asarray(silhouette, np.float32), 0, 2)
    return SketchMaps(np.ascontiguousarray(maps), trunk.astype(np.float32), cut, drawing_camera(size), window,
                      sketch_input.image)
