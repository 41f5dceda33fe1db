"""ViewRenderer: the one-per-process renderer that turns a tree and a rig (or given cameras) into named images per view.

In: TreeMesh, Skeleton, rig name or Cameras, output names, rng; out: a list of RenderedView (camera + images by name).
"""
from __future__ import annotations

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
from .strokes import trunk_strokes

__all__ = ["ViewRenderer", "RenderedView", "OUTPUTS", "DEFAULT_OUTPUTS", "OutputError", "check_outputs"]


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
                 rng: np.random.Generator):
        self.gl, self.camera, self.skeleton, self.split_orders, self.rng = gl, camera, skeleton, split_orders, rng

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
    def crown(self) -> np.ndarray:
        """(H, W) bool crown region from the leaves; a leafless tree's crown is its whole silhouette."""
        leaves = self.parts.leaves > 0
        return sketch.crown_region(leaves if leaves.any() else self.visible[1] > 0)


# Output name -> function of the view frame. Array types are the renderers contract (see renderers/__init__.py).
OUTPUTS: dict[str, Callable[[_ViewFrame], np.ndarray]] = {
    "depth": lambda f: f.visible[0],
    "depth01": lambda f: f.camera.depth01(f.visible[0]),
    "mask": lambda f: f.visible[1],
    "order": lambda f: f.visible[2],
    "normals": lambda f: f.normals,
    "silhouette": lambda f: silhouette_map(f.camera, f.visible[0], f.back),
    "silhouette_envelope": lambda f: envelope_silhouette_map(f.camera, f.visible[0], f.back),
    "depth_back": lambda f: f.back,
    "trunk_strokes": lambda f: f.trunk[0],
    "trunk_depth": lambda f: f.trunk[1],
    "sketch_tsn": lambda f: sketch.sketch_tsn(f.parts.bark > 0, f.parts.leaves > 0),
    "sketch_edges": lambda f: sketch.sketch_edges(f.normals, f.visible[1]),
    "sketch_strokes": lambda f: sketch.sketch_strokes(f.camera, f.skeleton),
    "sketch_strokes_brush": lambda f: sketch.sketch_strokes_brush(f.camera, f.skeleton),
    "sketch_crown": lambda f: sketch.sketch_crown(f.crown),
    "sketch_hand": lambda f: sketch.sketch_hand(f.camera, f.skeleton, f.crown, f.rng),
}
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
                               np.random.default_rng(int(view_seeds[index])))
            views.append(RenderedView(index, camera.name, camera, {n: OUTPUTS[n](frame) for n in names}))
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
