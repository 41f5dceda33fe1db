"""The GL side of the depth maps: one pyrender OffscreenRenderer per process drawing depth-only passes of a tree.

In: a TreeMesh uploaded once into `DepthRenderer` (its parts as `renderers.maps.tree_parts` splits it) and a
`Camera`; out: (H, W) float32 metric depth per part (`PartDepths`) and of the farthest surface (`back_depth`),
which `renderers.maps` turns into masks, order ids, normals and silhouettes.

Depth-only passes cost far less than a colour pass on Mesa's CPU rasterizer (docs/renderers.md) and carry no
anti-aliased colour that would blur ids. Each part of the tree (bark of each branch order, leaves) is drawn alone;
the nearest part wins per pixel (`maps.combine_parts`). The back surface for the silhouette comes from one more
pass with the depth row of the projection negated (the depth test then keeps the farthest surface) and x mirrored
(so back-face culling, which pyrender forces in depth-only passes, drops the near walls instead of the far ones);
the image is mirrored back into the front frame, pixel for pixel, as seed 000 mirrors its back camera.
`single_sample_renderer_class` is pyrender's Renderer with one sample per pixel, which every pass here uses.

GL platform: `use_headless_gl()` picks EGL for PyOpenGL unless PYOPENGL_PLATFORM is set; `DepthRenderer` calls it
before importing pyrender, so importing this module changes no environment variable. pyrender and OpenGL are
imported where a renderer is made, for that reason.
"""
from __future__ import annotations

import functools
import os
import sys

import numpy as np

from species.tree_mesh import TreeMesh

from .camera import Camera
from .maps import LEAVES, PartDepths, tree_parts

__all__ = ["DepthRenderer", "single_sample_renderer_class", "use_headless_gl", "DUMMY_PLANES"]

# The near and far planes pyrender is told (our projection matrices carry the real ones): its read-back
# linearises window depth with them, and `DepthRenderer` turns that back into window depth.
DUMMY_PLANES = (1.0, 2.0)


def use_headless_gl() -> None:
    """Make EGL PyOpenGL's platform unless the user chose one (PYOPENGL_PLATFORM): farm workers and CI have no
    display for GLX. PyOpenGL reads the variable once, when it is first imported, so this runs before anything
    imports pyrender or OpenGL (`DepthRenderer.__init__` does)."""
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def _destroy_egl_context(platform) -> None:
    """Destroy a pyrender EGL platform's context and forget its display, leaving the display initialised for the
    process's other renderers (pyrender's own delete_context terminates it)."""
    if platform._egl_display is None or platform._egl_context is None:
        return
    from OpenGL import EGL

    EGL.eglMakeCurrent(platform._egl_display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
    EGL.eglDestroyContext(platform._egl_display, platform._egl_context)
    platform._egl_context = None
    platform._egl_display = None


class DepthRenderer:
    """One pyrender OffscreenRenderer, reused across trees and views; draws depth-only passes of a tree's parts.

    `load(tree)` replaces the scene's meshes (uploaded once per tree); `part_depths(camera, ...)` and
    `back_depth(camera)` render passes. Resizes the GL framebuffer when a camera of another size comes.
    """

    def __init__(self, size: int = 256):
        use_headless_gl()
        import pyrender  # after use_headless_gl: PyOpenGL reads the platform on first import

        self._pyrender = pyrender
        self._renderer = pyrender.OffscreenRenderer(size, size)
        if os.environ.get("PYOPENGL_PLATFORM") == "egl":
            # pyrender frees a renderer dropped without close() (its __del__) by terminating the EGL display,
            # which is one per process: every other renderer alive died with it (EGL_BAD_CONTEXT at its next pass)
            platform = self._renderer._platform
            platform.delete_context = functools.partial(_destroy_egl_context, platform)
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
        """Free this renderer's GL objects and context (for EGL the context alone: the display, one per process,
        stays initialised for the other renderers; see __init__). pyrender's delete() would do the same through
        the patched delete_context, but then runs a full gc.collect(), which a close per library asset need not
        pay."""
        if self._renderer is None:
            return
        platform = self._renderer._platform
        if os.environ.get("PYOPENGL_PLATFORM") != "egl":
            self._renderer.delete()
        else:
            platform.make_current()
            self._renderer._renderer.delete()
            _destroy_egl_context(platform)
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
    from OpenGL import GL  # GL after use_headless_gl (see the module docstring)
    from pyrender.constants import RenderFlags
    from pyrender.renderer import Renderer

    class SingleSampleRenderer(Renderer):
        def _read_main_framebuffer(self, scene, flags):
            if not flags & RenderFlags.DEPTH_ONLY or sys.platform == "darwin":
                return super()._read_main_framebuffer(scene, flags)
            # pyrender's read-back of a depth-only pass, its values bit for bit (float32, the camera's planes),
            # without blitting the colour buffer nobody reads and with `where` for its masked writes (faster on the
            # twig atlas's large, mostly empty passes).
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
    import pyrender  # a DepthRenderer made first chose the GL platform

    class MatrixCamera(pyrender.camera.Camera):
        """A pyrender camera whose projection is a given 4x4 matrix (ours, built from K and the planes)."""

        def __init__(self, projection: np.ndarray):
            # Dummy planes: pyrender linearises read-back depth with them; DepthRenderer undoes it.
            super().__init__(znear=DUMMY_PLANES[0], zfar=DUMMY_PLANES[1])
            self._projection = projection

        def get_projection_matrix(self, width=None, height=None):
            return self._projection

    return MatrixCamera
