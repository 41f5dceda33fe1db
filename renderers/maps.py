"""Per-pixel maps from depth-only pyrender passes: metric depth, depth01, masks, branch order, normals, silhouette depth.

In: a TreeMesh uploaded once into `DepthRenderer` and a `Camera`; out: (H, W) arrays (see each function).

Every map comes from depth-only passes (far cheaper than a colour pass on Mesa's CPU rasterizer, see
docs/renderers.md, and with no anti-aliased colour that would blur ids). Each part of the tree (bark of each
branch order, leaves) is drawn alone; the nearest part wins per pixel, which gives depth, mask and order ids
exactly. The back surface for the silhouette comes from one more pass with the depth row of the projection
negated (the depth test then keeps the farthest surface) and x mirrored (so back-face culling, which pyrender
forces in depth-only passes, drops the near walls instead of the far ones); the image is mirrored back into the
front frame, pixel for pixel, as seed 000 mirrors its back camera.

GL platform: `use_headless_gl()` picks EGL for PyOpenGL unless PYOPENGL_PLATFORM is set; `DepthRenderer` calls it
before importing pyrender, so importing this module changes no environment variable.
"""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np

from species.meshing.textures import linear_to_srgb
from species.tree_mesh import TreeMesh

from .camera import Camera

__all__ = ["DepthRenderer", "PartDepths", "combine_parts", "normals_from_depth", "tangent_space_normals",
           "mask_albedo", "silhouette_map",
           "envelope_silhouette_map", "closed_mask", "use_headless_gl", "single_sample_renderer_class", "LEAVES",
           "DUMMY_PLANES", "tree_parts",
           "ENVELOPE_CLOSING_256", "ENVELOPE_SIGMA_256"]

LEAVES = "leaves"
# The near and far planes pyrender is told (our projection matrices carry the real ones): its read-back
# linearises window depth with them, and `DepthRenderer` turns that back into window depth.
DUMMY_PLANES = (1.0, 2.0)
# The crown envelope (`envelope_silhouette_map`), in pixels at 256 px, scaled with the image: gaps between leaves
# up to ~8 px are closed (the outline a person draws round a sparse crown), and the depth surfaces are the
# visible surfaces averaged over a Gaussian of sigma 8 px. At 4 px the target still holds the per-leaf depth that
# an edge sketch does not show (a blur oracle of the per-leaf front depth at 4 px scores 0.107, docs/training.md).
ENVELOPE_CLOSING_256 = 4
ENVELOPE_SIGMA_256 = 8.0


def use_headless_gl() -> None:
    """Make EGL PyOpenGL's platform unless the user chose one (PYOPENGL_PLATFORM): farm workers and CI have no
    display for GLX. PyOpenGL reads the variable once, when it is first imported, so this runs before anything
    imports pyrender or OpenGL (`DepthRenderer.__init__` does)."""
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def _bark_part(order: int) -> str:
    return f"bark{order}"


@dataclass
class PartDepths:
    """Depth of each part of the tree drawn alone, for one camera.

    depths : part name ("bark0", "bark1", ..., "leaves", or "bark" when bark orders are not split)
             -> (H, W) float32 metres, 0 where the part does not cover the pixel.
    """

    depths: dict[str, np.ndarray]

    @property
    def bark(self) -> np.ndarray:
        """(H, W) float32 metres, nearest bark surface (all orders), 0 where none."""
        parts = [d for name, d in self.depths.items() if name.startswith("bark")]
        return _nearest(parts)[0] if parts else np.zeros_like(self.depths[LEAVES])

    @property
    def leaves(self) -> np.ndarray:
        """(H, W) float32 metres, nearest leaf surface, 0 where none."""
        return self.depths[LEAVES]


def _nearest(depths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Nearest of several depth maps (0 = empty): (depth (H, W) float32, index (H, W) int64 of the winner, -1).
    On a tie the first map wins. A running minimum map by map: `argmin` over their (K, H, W) stack gives the same
    winners at several times the cost."""
    nearest = np.where(depths[0] > 0, depths[0], np.inf)
    winner = np.zeros(nearest.shape, np.int64)
    for index, depth in enumerate(depths[1:], 1):
        keyed = np.where(depth > 0, depth, np.inf)
        winner = np.where(keyed < nearest, index, winner)
        nearest = np.minimum(nearest, keyed)
    empty = np.isinf(nearest)
    return np.where(empty, 0.0, nearest).astype(np.float32), np.where(empty, -1, winner)


def combine_parts(parts: PartDepths) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visible depth, mask and order from per-part depths.

    Returns depth (H, W) float32 metres (0 background), mask (H, W) uint8 (0 background, 1 bark, 2 leaves) and
    order (H, W) uint8 (branch order + 1 on visible bark; 0 on background and leaves; bark parts named "bark"
    without an order count as order 0).
    """
    names = list(parts.depths)
    depth, winner = _nearest([parts.depths[n] for n in names])
    # Lookup tables by winner index; the extra last entry serves winner -1 (background).
    is_leaf = np.array([n == LEAVES for n in names] + [False])
    order_of = np.array([0 if n == LEAVES else 1 if n == "bark" else int(n[4:]) + 1 for n in names] + [0],
                        np.uint8)
    mask = np.where(winner < 0, 0, np.where(is_leaf[winner], 2, 1)).astype(np.uint8)
    return depth, mask, order_of[winner]


def normals_from_depth(camera: Camera, depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 surface normals from a depth map, in camera axes (x right, y down, z forward) mapped from
    [-1, 1] to [0, 255], facing the camera; background (depth 0) is 0."""
    fx, fy = camera.K[0, 0], camera.K[1, 1]
    cx, cy = camera.K[0, 2], camera.K[1, 2]
    z = depth.astype(np.float32)
    u = ((np.arange(z.shape[1], dtype=np.float32) - cx) / fx)[None, :]
    v = ((np.arange(z.shape[0], dtype=np.float32) - cy) / fy)[:, None]
    if camera.is_orthographic:
        x, y = np.broadcast_to(u, z.shape), np.broadcast_to(v, z.shape)
    else:
        x, y = u * z, v * z
    # Per-component gradients, cross product, normalisation and flip: no (H, W, 3) float stacks (each of those
    # steps on a stack, and numpy's reduction along its short last axis, cost more than the arithmetic).
    xu, yu, zu = (_unit_gradient(c, 1) for c in (x, y, z))
    xv, yv, zv = (_unit_gradient(c, 0) for c in (x, y, z))
    nx, ny, nz = yu * zv - zu * yv, zu * xv - xu * zv, xu * yv - yu * xv
    length = np.maximum(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-12)
    nx, ny, nz = nx / length, ny / length, nz / length
    towards = nz if camera.is_orthographic else nx * x + ny * y + nz * z
    away = towards > 0
    background = z <= 0
    out = np.empty(z.shape + (3,), np.uint8)
    for k, component in enumerate((nx, ny, nz)):
        texel = np.clip((np.where(away, -component, component) + 1.0) * 127.5, 0, 255).astype(np.uint8)
        texel[background] = 0
        out[..., k] = texel
    return out


def _unit_gradient(values: np.ndarray, axis: int) -> np.ndarray:
    """`np.gradient(values, axis=axis)` of a 2-D array (unit spacing, first-order edges; the same values: central
    differences halved, one-sided ones at the ends), without its generic set-up."""
    f = np.moveaxis(np.asarray(values), axis, 0)
    out = np.empty(f.shape, np.result_type(f, np.float32))
    out[1:-1] = (f[2:] - f[:-2]) / 2.0
    out[0] = f[1] - f[0]
    out[-1] = f[-1] - f[-2]
    return np.moveaxis(out, 0, axis)


def mask_albedo(mask: np.ndarray, bark_color, leaf_color) -> np.ndarray:
    """(H, W, 4) uint8 sRGB + alpha of a part mask (`combine_parts`: 1 bark, 2 leaves): bark texels in
    `bark_color`, leaf texels in `leaf_color` (linear RGB in [0, 1]) with alpha 255, the rest transparent; leaf
    texels too when `leaf_color` is None."""
    palette = np.zeros((256, 4), np.uint8)  # by mask value: a lookup, not a masked write per part
    for part, colour in ((1, bark_color), (2, leaf_color)):
        if colour is not None:
            palette[part] = (*np.round(linear_to_srgb(np.asarray(colour)) * 255).astype(np.uint8), 255)
    mask = np.asarray(mask, np.uint8)
    image = np.empty(mask.shape + (4,), np.uint8)
    # Each texel's four bytes gathered as one 32-bit word: several times faster than gathering rows of four.
    np.take(palette.view(np.uint32)[:, 0], mask, out=image.view(np.uint32)[..., 0])
    return image


def tangent_space_normals(camera: Camera, depth: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 normal-map texels of an image drawn as a texture seen head-on (x along the image's u,
    y up the image, z toward the viewer, [-1, 1] mapped to [0, 255]) from a depth map; flat (128, 128, 255) where
    not `covered` (H, W) bool."""
    camera_normals = normals_from_depth(camera, depth)
    texels = np.empty(camera_normals.shape, np.uint8)
    for k, (sign, flat) in enumerate(((1.0, 128), (-1.0, 128), (-1.0, 255))):  # camera y down, z forward
        tangent = sign * (camera_normals[..., k].astype(np.float32) / 127.5 - 1.0)
        texels[..., k] = np.clip(np.where(covered, np.round((tangent + 1.0) * 127.5), flat), 0, 255)
    return texels


def silhouette_map(camera: Camera, front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1]: R front depth01 (1 background), G front-to-back gap in depth01 units,
    B foreground mask; from front and back metric depth (H, W) float32 metres of the same camera."""
    mask = front > 0
    f01 = camera.depth01(front)
    b01 = camera.depth01(np.where(mask, back, 0.0))
    gap = np.where(mask, np.clip(b01 - f01, 0.0, 1.0), 0.0)
    return np.stack([f01, gap, mask.astype(np.float32)], axis=-1).astype(np.float32)


def closed_mask(mask: np.ndarray, radius_px: int) -> np.ndarray:
    """(H, W) bool: a mask with gaps narrower than about 2 radius_px pixels closed (dilate, then erode, with a
    (2r+1)-pixel ellipse), padded so the closing is not clipped at the image border."""
    import cv2

    if radius_px <= 0:
        return np.asarray(mask, bool)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    pad = radius_px + 1
    padded = np.pad(np.asarray(mask, np.uint8), pad)
    return cv2.morphologyEx(padded, cv2.MORPH_CLOSE, kernel)[pad:-pad, pad:-pad] > 0


def _smooth_within(values: np.ndarray, weight: np.ndarray, region: np.ndarray, sigma: float) -> np.ndarray:
    """(H, W) float64: the Gaussian average of `values` over the pixels where weight > 0 (normalised
    convolution), at every pixel of `region`; pixels of the region too far from any weight (a filled hole wider
    than a few sigma) take the average at 4 sigma, then the overall mean."""
    import cv2

    out = np.full(values.shape, float(values[weight > 0].mean()), np.float64)
    todo = region.copy()
    w = weight.astype(np.float64)
    for s in (sigma, 4.0 * sigma):
        num = cv2.GaussianBlur(values * w, (0, 0), s, borderType=cv2.BORDER_CONSTANT)
        den = cv2.GaussianBlur(w, (0, 0), s, borderType=cv2.BORDER_CONSTANT)
        reached = todo & (den > 1e-3)
        out[reached] = num[reached] / den[reached]
        todo &= ~reached
    return out


def envelope_silhouette_map(camera: Camera, front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1], the crown envelope in `silhouette_map`'s encoding: R front depth01 (1
    background), G front-to-back gap, B mask; from front and back metric depth (H, W) float32 metres.

    The mask is the tree's silhouette closed (ENVELOPE_CLOSING_256 px at 256 px) with its holes filled: one region
    per crown, as a person outlines it. Front and back are the visible front and back depth01 averaged over a
    Gaussian (ENVELOPE_SIGMA_256 px) within the silhouette and carried into the closed gaps: smooth surfaces
    that an outline sketch determines, where the per-leaf depth of `silhouette` varies from pixel to pixel
    (standard deviation 0.16-0.20 within a crown) with nothing in an edge sketch to show it. The seed 000
    growth fills this span with markers, so it is the map reconstruction needs (reconstruct.from_sketch)."""
    from scipy import ndimage

    mask = front > 0
    scale = max(mask.shape) / 256.0
    if not mask.any():
        return silhouette_map(camera, front, back)
    crown = ndimage.binary_fill_holes(closed_mask(mask, max(1, round(ENVELOPE_CLOSING_256 * scale))))
    sigma = ENVELOPE_SIGMA_256 * scale
    f01 = camera.depth01(front).astype(np.float64)
    b01 = camera.depth01(np.where(mask, back, 0.0)).astype(np.float64)
    front_env = np.clip(_smooth_within(f01, mask, crown, sigma), 0.0, 1.0)
    back_env = np.clip(_smooth_within(np.maximum(b01, f01), mask, crown, sigma), 0.0, 1.0)
    gap = np.where(crown, np.maximum(back_env - front_env, 0.0), 0.0)
    return np.stack([np.where(crown, front_env, 1.0), gap, crown.astype(np.float64)], axis=-1).astype(np.float32)


def tree_parts(tree: TreeMesh) -> dict[str, tuple[np.ndarray, np.ndarray, bool]]:
    """The parts a renderer draws a tree in: name -> (vertices, faces, double_sided), the bark one part per
    branch order (its `order` attribute; order 0 without one), then the leaves; empty parts left out."""
    parts = {}
    bark = tree.bark
    if bark.n_faces:
        order = bark.attributes.get("order")
        face_order = np.zeros(bark.n_faces, np.uint8) if order is None else np.asarray(order)[bark.faces[:, 0]]
        for value in np.unique(face_order):
            parts[_bark_part(int(value))] = (bark.vertices, bark.faces[face_order == value], False)
    if tree.leaves.n_faces:
        parts[LEAVES] = (tree.leaves.vertices, tree.leaves.faces, True)
    return parts


class DepthRenderer:
    """One pyrender OffscreenRenderer, reused across trees and views; draws depth-only passes of a tree's parts.

    `load(tree)` replaces the scene's meshes (uploaded once per tree); `part_depths(camera, ...)` and
    `back_depth(camera)` render passes. Resizes the GL framebuffer when a camera of another size comes.
    """

    def __init__(self, size: int = 256):
        use_headless_gl()
        import pyrender

        self._pyrender = pyrender
        self._renderer = pyrender.OffscreenRenderer(size, size)
        # Swap in a renderer without multisampling (see single_sample_renderer_class).
        self._renderer._renderer = single_sample_renderer_class()(size, size)
        self._scene = pyrender.Scene(bg_color=[1.0, 1.0, 1.0, 1.0])
        self._camera_node = None
        self._mesh_nodes: dict[str, object] = {}
        self._tree: TreeMesh | None = None

    @property
    def part_names(self) -> list[str]:
        return list(self._mesh_nodes)

    def close(self) -> None:
        """Free this renderer's GL objects and context.

        pyrender's own delete() also calls eglTerminate, and the EGL display is one per process: that would
        break every other renderer alive in the process, so for EGL the context is destroyed and the display
        left initialised.
        """
        if self._renderer is None:
            return
        platform = self._renderer._platform
        if os.environ.get("PYOPENGL_PLATFORM") != "egl":
            self._renderer.delete()
        else:
            from OpenGL import EGL

            platform.make_current()
            self._renderer._renderer.delete()
            EGL.eglMakeCurrent(platform._egl_display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
            EGL.eglDestroyContext(platform._egl_display, platform._egl_context)
            # Forget the display too, so pyrender's OffscreenRenderer.__del__ has nothing left to terminate.
            platform._egl_context = None
            platform._egl_display = None
        self._renderer = None
        self._mesh_nodes = {}
        self._tree = None

    def _mesh(self, vertices: np.ndarray, faces: np.ndarray, double_sided: bool):
        # pyrender culls back faces in depth-only passes whatever the material says: leaf cards go in twice,
        # once per winding; bark is closed and wound outward (TreeMesh contract), so culling is correct for it.
        pr = self._pyrender
        if double_sided:
            faces = np.concatenate([faces, faces[:, ::-1]])
        return pr.Mesh([pr.Primitive(positions=vertices, indices=faces)])

    def load(self, tree: TreeMesh) -> None:
        """Put a tree's bark (one mesh per branch order, from the bark `order` attribute) and leaves in the scene."""
        if tree is self._tree:
            return
        for node in self._mesh_nodes.values():
            self._scene.remove_node(node)
        self._mesh_nodes = {name: self._scene.add(self._mesh(vertices, faces, double_sided))
                            for name, (vertices, faces, double_sided) in tree_parts(tree).items()}
        self._tree = tree

    def _set_camera(self, camera: Camera, reverse_depth: bool) -> None:
        projection = camera.opengl_projection(reverse_depth)
        if reverse_depth:
            # Mirror x as well: the screen winding flips, so culling keeps the faces turned away from the
            # camera (the far walls of the bark); `_pass` mirrors the image back.
            projection[0] = -projection[0]
        gl_camera = _matrix_camera_class()(projection)
        if self._camera_node is None:
            self._camera_node = self._scene.add(gl_camera, pose=camera.opengl_pose())
        else:
            self._camera_node.camera = gl_camera
            self._scene.set_pose(self._camera_node, camera.opengl_pose())
        self._scene.main_camera_node = self._camera_node
        if (self._renderer.viewport_width, self._renderer.viewport_height) != (camera.width, camera.height):
            self._renderer.viewport_width, self._renderer.viewport_height = camera.width, camera.height

    def _draw(self, camera: Camera, visible: set[str], reverse_depth: bool = False) -> np.ndarray:
        """Draw the visible parts depth-only through `camera`; what pyrender's read-back returns."""
        for name, node in self._mesh_nodes.items():
            node.mesh.is_visible = name in visible
        self._set_camera(camera, reverse_depth)
        flags = self._pyrender.RenderFlags.DEPTH_ONLY | self._pyrender.RenderFlags.SKIP_CULL_FACES
        return self._renderer.render(self._scene, flags=flags)

    def _pass(self, camera: Camera, visible: set[str], reverse_depth: bool = False) -> np.ndarray:
        """(H, W) float32 metres of the nearest (farthest if reverse_depth) surface of the visible parts."""
        return self._metric_depth(self._draw(camera, visible, reverse_depth), camera, reverse_depth)

    @staticmethod
    def _metric_depth(linear: np.ndarray, camera: Camera, reverse_depth: bool = False) -> np.ndarray:
        """(H, W) float32 metres from pyrender's read-back of a pass through `camera` (0 where empty)."""
        if reverse_depth:
            linear = linear[:, ::-1]
        # pyrender linearised the window depth with the dummy planes (DUMMY_PLANES): undo, then use ours. Only
        # where something was drawn (a twig atlas's 2048 x 577 passes are mostly empty).
        near, far = DUMMY_PLANES
        hit = linear > 0
        depth = np.zeros(linear.shape, np.float32)
        window = far / (far - near) - (far * near / (far - near)) / linear[hit]  # 2 - 2 / linear for (1, 2)
        depth[hit] = camera.depth_from_window(window, reverse_depth)
        return depth

    def part_depths(self, camera: Camera, split_orders: bool) -> PartDepths:
        """Depth of bark and leaves drawn apart (bark split per order when `split_orders`)."""
        names = self.part_names
        bark = [n for n in names if n.startswith("bark")]
        depths = {}
        if split_orders:
            for name in bark:
                depths[name] = self._pass(camera, {name})
        elif bark:
            depths["bark"] = self._pass(camera, set(bark))
        if LEAVES in names:
            depths[LEAVES] = self._pass(camera, {LEAVES})
        else:
            depths[LEAVES] = np.zeros((camera.height, camera.width), np.float32)
        return PartDepths(depths)

    def back_depth(self, camera: Camera, front: np.ndarray) -> np.ndarray:
        """(H, W) float32 metres, the farthest surface of the whole tree along each pixel's ray, given the
        front depth (H, W) float32 metres of the same camera: never nearer than the front (a ray through an open
        tube end or the edge of a leaf, sampled a hair apart in the mirrored pass, may find no far wall); 0 where
        the front is empty."""
        back = self._pass(camera, set(self.part_names), reverse_depth=True)
        return np.where(front > 0, np.maximum(back, front), 0.0).astype(np.float32)


@functools.cache
def single_sample_renderer_class():
    """pyrender's Renderer with its 4x multisampled framebuffer made single-sample.

    Why: pyrender resolves depth from the 4x buffer by taking one sample, which sits off the pixel centre, so
    masks came out shifted by a fraction of a pixel; and llvmpipe shades every sample, so 4x costs up to 4x.
    With one sample, a pixel is covered exactly when a triangle covers its centre. Relies on pyrender 0.1.45
    internals (pinned in pyproject.toml).
    """
    import sys

    from OpenGL import GL
    from pyrender.constants import RenderFlags
    from pyrender.renderer import Renderer

    class SingleSampleRenderer(Renderer):
        def _read_main_framebuffer(self, scene, flags):
            if not flags & RenderFlags.DEPTH_ONLY or sys.platform == "darwin":
                return super()._read_main_framebuffer(scene, flags)
            # pyrender's read-back of a depth-only pass, its values bit for bit (float32, the camera's planes),
            # without blitting the colour buffer nobody reads and with `where` for its masked writes (the twig
            # atlas's 2048 x 530 passes: about 3x faster).
            camera = scene.main_camera_node.camera
            return self.linear_depth(self.window_depth(), camera.znear, camera.zfar)

        @staticmethod
        def linear_depth(window: np.ndarray, near: float, far: float) -> np.ndarray:
            """(H, W) float32, pyrender's linear depth of a window depth read-back, 0 where nothing was drawn."""
            ndc = 2.0 * window - 1.0
            linear = (2.0 * near * far) / (far + near - ndc * (far - near))
            return np.where(window == 1.0, np.float32(0.0), linear)

        def window_depth(self) -> np.ndarray:
            """(H, W) float32 window depth of the last pass, image rows top first (1.0 where nothing was drawn):
            the depth buffer copied out of the render target and read back."""
            width, height = self._main_fb_dims
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb_ms)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb)
            GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height, GL.GL_DEPTH_BUFFER_BIT, GL.GL_NEAREST)
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb)
            return np.frombuffer(GL.glReadPixels(0, 0, width, height, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT),
                                 np.float32).reshape(height, width)[::-1]

        def _configure_main_framebuffer(self):
            super()._configure_main_framebuffer()
            if getattr(self, "_single_sample_dims", None) != self._main_fb_dims:
                w, h = self._main_fb_dims
                for buffer, fmt in ((self._main_cb_ms, GL.GL_RGBA), (self._main_db_ms, GL.GL_DEPTH_COMPONENT24)):
                    GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, buffer)
                    GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, 0, fmt, w, h)
                self._single_sample_dims = self._main_fb_dims

    return SingleSampleRenderer


@functools.cache
def _matrix_camera_class():
    import pyrender

    class MatrixCamera(pyrender.camera.Camera):
        """A pyrender camera whose projection is a given 4x4 matrix (ours, built from K and the planes)."""

        def __init__(self, projection: np.ndarray):
            # Dummy planes: pyrender linearises read-back depth with them; DepthRenderer undoes it.
            super().__init__(znear=DUMMY_PLANES[0], zfar=DUMMY_PLANES[1])
            self._projection = projection

        def get_projection_matrix(self, width=None, height=None):
            return self._projection

    return MatrixCamera
