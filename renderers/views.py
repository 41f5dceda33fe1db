"""ViewRenderer: the one-per-process renderer that turns a tree and a rig (or given cameras) into named images per view.

In: TreeMesh, Skeleton, rig name or Cameras, output names, rng; out: a list of RenderedView (camera + images by name).
"""
from __future__ import annotations

from collections.abc import Set
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, Sequence

import numpy as np

from species.errors import TreefarmError
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh

from . import sketch
from .camera import Camera, CameraError, make_rig, rig_parts
from .gl_depth import DepthRenderer
from .maps import combine_parts, envelope_silhouette_map, normals_from_depth, silhouette_map
from .photo_backdrop import photo_view
from .strokes import trunk_strokes

__all__ = ["ViewRenderer", "RenderedView", "Output", "OUTPUTS", "FLOAT_OUTPUTS", "METRIC_MAPS", "LABEL_MAPS",
           "DEFAULT_OUTPUTS", "OutputError", "check_outputs"]


LEAFLESS_PHOTO_SHARE = 0.3  # of the "photo" views, those showing the tree without its leaves


class OutputError(TreefarmError):
    """An unknown output (map or sketch style) name."""


@dataclass
class RenderedView:
    """One view of one tree: its index in the rig, name ("front", ...), camera, and images by output name."""

    index: int
    name: str
    camera: Camera
    images: dict[str, np.ndarray] = field(default_factory=dict)


class _ViewFrame:
    """Everything one view's outputs are made from, each computed once and only when an output asks for it."""

    def __init__(self, gl: DepthRenderer, camera: Camera, skeleton: Skeleton, split_orders: bool,
                 rng: np.random.Generator, colours: tuple):
        self.gl, self.camera, self.skeleton, self.split_orders, self.rng = gl, camera, skeleton, split_orders, rng
        self.colours = colours  # the tree's bark and leaf base colours (linear RGB), for the "photo" output

    @cached_property
    def parts(self):
        return self.gl.part_depths(self.camera, self.split_orders)

    @cached_property
    def visible(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return combine_parts(self.parts)

    @cached_property
    def back(self) -> np.ndarray:
        return self.gl.back_depth(self.camera, self.visible[0])

    @cached_property
    def normals(self) -> np.ndarray:
        return normals_from_depth(self.camera, self.visible[0])

    @cached_property
    def trunk(self) -> tuple[np.ndarray, np.ndarray]:
        return trunk_strokes(self.camera, self.skeleton)

    @cached_property
    def photo(self) -> tuple[np.ndarray, np.ndarray]:
        """(photo (H, W, 3) uint8, its mask (H, W) uint8 1 bark, 2 leaves): a photo-like view over a random
        backdrop; one view in LEAFLESS_PHOTO_SHARE shows the tree in winter (bark only, the bark behind the leaves
        uncovered), so a mask network sees both seasons. Drawn from the view's rng: the season first."""
        labels, normals = self.visible[1], self.normals
        bark = self.parts.bark
        if self.rng.random() < LEAFLESS_PHOTO_SHARE and (bark > 0).any():
            labels, normals = (bark > 0).astype(np.uint8), normals_from_depth(self.camera, bark)
        return photo_view(self.rng, labels, normals, *self.colours), labels

    @cached_property
    def crown(self) -> np.ndarray:
        """(H, W) bool crown region from the leaves; a leafless tree's crown is its whole silhouette."""
        leaves = self.parts.leaves > 0
        return sketch.crown_region(leaves if leaves.any() else self.visible[1] > 0)


@dataclass(frozen=True)
class Output:
    """One render output: how a view frame makes it, and the array it comes back as (the renderers contract,
    renderers/__init__.py); the dataset stores a uint8 output as an 8-bit PNG, a float32 one as a 16-bit PNG
    with scale and offset.

    make   : function of the view frame -> (H, W) or (H, W, 3) array of `dtype`.
    dtype  : numpy.uint8 or numpy.float32.
    metric : float32 in metres with 0 = background (depth maps); False for uint8 and for float32 in [0, 1].
    label  : uint8 class labels (0, 1, 2, ...), not grey levels: shown spread over the grey range.
    mask_channel : the channel of an (H, W, C) output that is its foreground mask (the silhouette maps): a picture
             of the output shows the pixels outside the mask as background, not as the other channels' values there.
    """

    make: Callable[[_ViewFrame], np.ndarray]
    dtype: np.dtype
    metric: bool = False
    label: bool = False
    mask_channel: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "dtype", np.dtype(self.dtype))
        if self.dtype not in (np.uint8, np.float32):
            raise OutputError(f"an output of dtype {self.dtype} is invalid: allowed uint8 or float32")
        if self.metric and self.dtype != np.float32:
            raise OutputError(f"a metric output of dtype {self.dtype} is invalid: allowed float32 (metres)")
        if self.label and self.dtype != np.uint8:
            raise OutputError(f"a label output of dtype {self.dtype} is invalid: allowed uint8 (class labels)")

    @property
    def is_float(self) -> bool:
        return self.dtype == np.float32


_U8, _F32 = np.uint8, np.float32
# Output name -> its entry: adding an output is one entry here (FLOAT_OUTPUTS and METRIC_MAPS follow from it).
OUTPUTS: dict[str, Output] = {
    "depth": Output(lambda f: f.visible[0], _F32, metric=True),
    "depth01": Output(lambda f: f.camera.depth01(f.visible[0]), _F32),
    "mask": Output(lambda f: f.visible[1], _U8, label=True),
    "order": Output(lambda f: f.visible[2], _U8, label=True),
    "normals": Output(lambda f: f.normals, _U8),
    "silhouette": Output(lambda f: silhouette_map(f.camera, f.visible[0], f.back), _F32, mask_channel=2),
    "silhouette_envelope": Output(lambda f: envelope_silhouette_map(f.camera, f.visible[0], f.back), _F32,
                                  mask_channel=2),
    "depth_back": Output(lambda f: f.back, _F32, metric=True),
    "trunk_strokes": Output(lambda f: f.trunk[0], _U8),
    "trunk_depth": Output(lambda f: f.trunk[1], _F32),
    "sketch_tsn": Output(lambda f: sketch.sketch_tsn(f.parts.bark > 0, f.parts.leaves > 0), _U8),
    "sketch_edges": Output(lambda f: sketch.sketch_edges(f.normals, f.visible[1]), _U8),
    "sketch_strokes": Output(lambda f: sketch.sketch_strokes(f.camera, f.skeleton), _U8),
    "sketch_strokes_brush": Output(lambda f: sketch.sketch_strokes_brush(f.camera, f.skeleton), _U8),
    "sketch_crown": Output(lambda f: sketch.sketch_crown(f.crown), _U8),
    "sketch_hand": Output(lambda f: sketch.sketch_hand(f.camera, f.skeleton, f.crown, f.rng), _U8),
    # A photo-like colour view over a random outdoor backdrop, and the tree's pixels in it (the tree mask
    # network's input and target; "mask" differs from it in the photos that show the tree leafless).
    "photo": Output(lambda f: f.photo[0], _U8),
    "photo_mask": Output(lambda f: f.photo[1], _U8, label=True),
}


class _OutputNames(Set):
    """The names of the OUTPUTS entries that pass a test, read from OUTPUTS at each use: an output registered
    later (a plugin's, a test's) is in it too, which a set computed at import would miss."""

    def __init__(self, test: Callable[[Output], bool], description: str):
        self._test, self._description = test, description

    def __contains__(self, name) -> bool:
        return name in OUTPUTS and self._test(OUTPUTS[name])

    def __iter__(self):
        return (name for name, output in list(OUTPUTS.items()) if self._test(output))

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __repr__(self) -> str:
        return f"<{self._description}: {', '.join(self)}>"


# The outputs stored as float maps (16-bit PNG with `<name>_scale` and `<name>_offset` columns), those of them
# in metres with 0 = background, and the uint8 maps of class labels.
FLOAT_OUTPUTS = _OutputNames(lambda output: output.is_float, "float32 outputs")
METRIC_MAPS = _OutputNames(lambda output: output.metric, "metric outputs")
LABEL_MAPS = _OutputNames(lambda output: output.label, "label outputs")
DEFAULT_OUTPUTS = ("depth", "mask", "silhouette", "trunk_strokes", "trunk_depth", "sketch_tsn")


def check_outputs(outputs: Sequence[str]) -> tuple[str, ...]:
    """The output names as a tuple, or an OutputError naming the first unknown one and listing the allowed."""
    if isinstance(outputs, str):
        outputs = [outputs]
    names = tuple(outputs)
    for name in names:
        if name not in OUTPUTS:
            raise OutputError(f"output {name!r} is unknown: allowed {', '.join(OUTPUTS)}")
    if not names:
        raise OutputError(f"no outputs asked for: choose from {', '.join(OUTPUTS)}")
    return names


class ViewRenderer:
    """The farm's renderer: create once per process (it owns the GL context), call `render` for every tree.

    size : image width and height in pixels; may be changed between calls (the framebuffer follows).
    """

    def __init__(self, size: int = 256):
        self.size = int(size)
        self._gl = DepthRenderer(self.size)

    def close(self) -> None:
        self._gl.close()

    def cameras(self, tree: TreeMesh, rig: str, rng: np.random.Generator) -> list[Camera]:
        """The rig's cameras framed on the tree's vertices (what `render` uses)."""
        points = np.concatenate([tree.bark.vertices, tree.leaves.vertices])
        return make_rig(rig, points, self.size, rng)

    def render(self, tree: TreeMesh, skeleton: Skeleton, rig: str, outputs: Sequence[str],
               rng: np.random.Generator) -> list[RenderedView]:
        """Render each view of the rig and the named outputs (see OUTPUTS) for each.

        The rng is drawn in a fixed order: rig jitter (":jitter" rigs only), then one seed per view for the
        hand-drawn style; the same inputs and rng state give identical arrays.
        """
        names = check_outputs(outputs)
        rig_parts(rig)
        _check_rng(rng)
        _check_tree(tree)
        return self._render(tree, skeleton, self.cameras(tree, rig, rng), names, rng)

    def render_cameras(self, tree: TreeMesh, skeleton: Skeleton, cameras: Sequence[Camera],
                       outputs: Sequence[str], rng: np.random.Generator) -> list[RenderedView]:
        """Render the named outputs in given cameras (each with its own image size): a reconstruction seen
        in its input view and in unseen views, for the metrics. Views keep the cameras' order and names.

        The rng gives one seed per view for the hand-drawn style; `render(tree, skeleton, rig, ...)` is this
        call on `cameras(tree, rig, rng)`, so a plain rig's cameras give its views byte for byte.
        """
        names = check_outputs(outputs)
        cameras = _check_cameras(cameras)
        _check_rng(rng)
        _check_tree(tree)
        return self._render(tree, skeleton, cameras, names, rng)

    def silhouette_masks(self, tree: TreeMesh, cameras: Sequence[Camera]) -> np.ndarray:
        """(V, H, W) bool, True where the tree (bark or leaves) covers a pixel in each camera: the "mask" output
        above 0, without a skeleton or rng, for silhouette IoU. The cameras must share one image size; a tree
        with no triangles (an empty reconstruction) covers no pixel."""
        cameras = _check_cameras(cameras)
        sizes = sorted({(c.width, c.height) for c in cameras})
        if len(sizes) > 1:
            raise CameraError(f"cameras of image sizes {sizes} (width, height) cannot stack into one mask array: "
                              "allowed one size for all")
        self._gl.load(tree)
        return np.stack([combine_parts(self._gl.part_depths(c, False))[1] > 0 for c in cameras])

    def _render(self, tree: TreeMesh, skeleton: Skeleton, cameras: list[Camera], names: tuple[str, ...],
                rng: np.random.Generator) -> list[RenderedView]:
        view_seeds = rng.integers(0, 2**63, len(cameras))
        self._gl.load(tree)
        views = []
        for index, camera in enumerate(cameras):
            frame = _ViewFrame(self._gl, camera, skeleton, "order" in names,
                               np.random.default_rng(int(view_seeds[index])), (tree.bark_color, tree.leaf_color))
            views.append(RenderedView(index, camera.name, camera, {n: OUTPUTS[n].make(frame) for n in names}))
        return views


def _check_rng(rng) -> None:
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")


def _check_tree(tree: TreeMesh) -> None:
    if tree.n_faces == 0:
        raise TreefarmError(f"tree {tree.name!r} has no triangles to render")


def _check_cameras(cameras) -> list[Camera]:
    """The cameras as a list, or a CameraError when there are none or one is not a `Camera` (a rig name is
    not: `render` takes those)."""
    if isinstance(cameras, (str, Camera)) or not isinstance(cameras, Sequence):
        raise CameraError(f"cameras must be a sequence of Camera, got a {type(cameras).__name__}: pass a list "
                          "(a rig name goes to `render`)")
    cameras = list(cameras)
    if not cameras:
        raise CameraError("no cameras given: allowed one Camera or more")
    for i, camera in enumerate(cameras):
        if not isinstance(camera, Camera):
            raise CameraError(f"camera {i} is a {type(camera).__name__}, not a Camera: allowed Camera objects only")
    return cameras
