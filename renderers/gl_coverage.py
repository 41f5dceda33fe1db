"""Coverage and depth passes drawn straight from uploaded primitives: silhouettes and impostor slices in one draw.

In: a TreeMesh (or named groups of its faces) uploaded once into `CoverageRenderer` and a `Camera`; out: (H, W)
bool coverage masks (`coverage`) and (H, W) float32 metric depths of parts (`part_depths`) or face groups
(`group_depth`), the same pixels and depths as `renderers.gl_depth.DepthRenderer`'s scene passes. The library's
LOD and impostor quality checks and `renderers.impostor`'s atlases draw through it.
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
from collections import OrderedDict

import numpy as np

from species.errors import TreefarmError
from species.tree_mesh import TreeMesh

from .camera import Camera
from .gl_depth import DUMMY_PLANES, DepthRenderer, single_sample_renderer_class
from .maps import tree_parts

__all__ = ["CoverageRenderer", "RenderPassError"]


class RenderPassError(TreefarmError):
    """A pass this renderer cannot draw (the farthest surface needs back-face culling, which it does not do)."""


class CoverageRenderer(DepthRenderer):
    """The farm's depth renderer for coverage: a tree's silhouette in one draw, its parts' depths, and named
    groups of faces uploaded once and drawn in any combination (the impostor's azimuth sectors).

    A tree is drawn as its files' materials draw it: the bark single-sided (back faces culled, as an engine culls
    the bark material, which is not double-sided), the leaves double-sided without culling, so leaf cards go in
    once, not once per winding (pyrender culls every depth-only draw; for leafy trees that halves the triangles
    drawn). Culling the bark's far walls also halves the bark's cost (docs/library.md). Whatever
    is not closed bark (twig cards, faces pressed onto them) goes in `leaves`. Named groups (`load_groups`:
    slices of the tree, faces pressed into an atlas) are drawn without culling. The nearest surface wins per
    pixel; only `back_depth`, which relies on culling, is not available here.

    Every pass draws primitives uploaded apart from pyrender's scene, with its program, framebuffer and
    read-back but not its scene walk (`_direct_pass_renderer_class`): the same pixels and depths, and `coverage`
    draws into a one-byte target without depth, which is cheaper (`benchmarks/bench_library.py`).
    """

    def __init__(self, size: int = 256):
        super().__init__(size)
        self._renderer._renderer = _direct_pass_renderer_class()(size, size)
        self._cover_tree, self._cover_primitives = None, []  # `coverage`'s tree and its uploaded primitives
        self._groups: dict[str, object] = {}  # `load_groups`' uploaded primitives by name
        self._parts: dict[str, object] = {}  # `load`'s, by part name (`renderers.maps.tree_parts`)

    @property
    def part_names(self) -> list[str]:
        return list(self._parts)

    def load(self, tree: TreeMesh) -> None:
        """Upload a tree's parts (`renderers.maps.tree_parts`: bark per branch order, culled; leaves drawn from both
        sides) for `part_depths`."""
        if tree is self._tree:
            return
        with self._current():
            self._free(self._parts.values())
            self._parts = {name: self._upload(vertices, faces, not double_sided)
                           for name, (vertices, faces, double_sided) in tree_parts(tree).items()}
        self._tree = tree

    def _pass(self, camera: Camera, visible: set[str], reverse_depth: bool = False) -> np.ndarray:
        """(H, W) float32 metres of the nearest surface of the visible loaded parts (a direct depth pass; the
        farthest-surface pass is `back_depth`'s alone, refused below)."""
        return self._depth_of([self._parts[name] for name in sorted(visible & set(self._parts))], camera)

    def back_depth(self, camera: Camera, front: np.ndarray) -> np.ndarray:
        raise RenderPassError("back_depth needs back-face culling: use renderers.gl_depth.DepthRenderer for it")

    def coverage(self, tree: TreeMesh, camera: Camera) -> np.ndarray:
        """(H, W) bool, pixels whose centre a triangle of `tree` covers (leaf cards as opaque quads)."""
        with self._current():
            if tree is not self._cover_tree:
                self._free(self._cover_primitives)
                self._cover_primitives = [self._upload(part.vertices, part.faces, culled)
                                          for part, culled in ((tree.bark, True), (tree.leaves, False))
                                          if part.n_faces]
                self._cover_tree = tree
            return self._renderer._renderer.coverage_pass(self._cover_primitives, *self._view_projection(camera))

    def load_groups(self, groups: dict[str, tuple[np.ndarray, np.ndarray, bool]]) -> None:
        """Upload named face groups for `group_depth`, replacing those loaded before: name -> (vertices (V, 3)
        float metres, faces (F, 3) int, double_sided); empty groups are left out."""
        with self._current():
            self._free(self._groups.values())
            # Slices and pressed faces are not closed: drawn from both sides.
            self._groups = {name: self._upload(vertices, faces, False)
                            for name, (vertices, faces, _) in groups.items() if len(faces)}

    def group_depth(self, camera: Camera, names) -> np.ndarray:
        """(H, W) float32 metres, the nearest surface of the named groups (those loaded), 0 where none."""
        primitives = [self._groups[name] for name in sorted(set(names) & set(self._groups))]
        if not primitives:
            return np.zeros((camera.height, camera.width), np.float32)
        return self._depth_of(primitives, camera)

    def _depth_of(self, primitives, camera: Camera) -> np.ndarray:
        with self._current():
            linear = self._renderer._renderer.depth_pass(primitives, *self._view_projection(camera))
        return self._metric_depth(linear, camera)

    def close(self) -> None:
        self._cover_tree, self._cover_primitives, self._groups, self._parts = None, [], {}, {}  # freed with it
        super().close()

    @contextlib.contextmanager
    def _current(self):
        """This renderer's GL context made current for the block (as pyrender's own passes do)."""
        platform = self._renderer._platform
        platform.make_current()
        try:
            yield
        finally:
            platform.make_uncurrent()

    def _upload(self, vertices: np.ndarray, faces: np.ndarray, culled: bool):
        """A primitive in GL buffers (the context current), drawn by the direct passes; `culled`: back faces
        culled (a tree's bark) or drawn too."""
        primitive = self._pyrender.Primitive(positions=vertices, indices=faces)
        primitive._add_to_context()
        primitive.culled = culled
        return primitive

    @staticmethod
    def _free(primitives) -> None:
        for primitive in primitives:
            primitive._remove_from_context()

    def _view_projection(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """The view and projection matrices pyrender's own pass would give the shaders for `camera` (its scene
        camera posed as `_draw` poses it), so a direct pass draws the same pixels as a scene pass."""
        self._set_camera(camera, False)
        gl = self._renderer._renderer
        gl.viewport_width, gl.viewport_height = camera.width, camera.height
        return gl._get_camera_matrices(self._scene)


@functools.cache
def _direct_pass_renderer_class():
    """The single-sample pyrender Renderer of `renderers.gl_depth` with passes that draw uploaded primitives directly.

    pyrender 0.1.45 (pinned) walks its scene on every pass and culls every depth-only primitive. These passes use
    its depth-only program, framebuffer and read-back, draw a list of primitives (each marked `culled`: a tree's
    bark, back faces culled; otherwise both windings, in one draw), and skip the walk.
    """
    from OpenGL import GL  # after use_headless_gl, which DepthRenderer.__init__ runs (renderers.gl_depth)
    from pyrender.constants import ProgramFlags, RenderFlags

    _DEPTH_ONLY = RenderFlags.DEPTH_ONLY | RenderFlags.SKIP_CULL_FACES
    _COVER_TARGETS = 8
    _IDENTITY = np.eye(4)  # the model matrix: trees are uploaded in world coordinates

    class DirectPassRenderer(single_sample_renderer_class()):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            # (width, height) -> (framebuffer, renderbuffer), least recently used first
            self._cover_targets: OrderedDict[tuple[int, int], tuple[int, int]] = OrderedDict()

        def coverage_pass(self, primitives, view: np.ndarray, projection: np.ndarray) -> np.ndarray:
            """(H, W) bool (the viewport's size), the pixels the primitives cover: into a one-byte colour target
            with no depth buffer (a mask needs no nearest surface, and llvmpipe draws it faster so), the same
            vertex transform, so the same pixels."""
            width, height = self.viewport_width, self.viewport_height
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self._cover_target(width, height))
            GL.glViewport(0, 0, width, height)
            GL.glDisable(GL.GL_DEPTH_TEST)
            GL.glClearColor(0.0, 0.0, 0.0, 0.0)
            GL.glClear(GL.GL_COLOR_BUFFER_BIT)
            self._draw_primitives(primitives, view, projection)
            GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)  # rows of one byte a pixel, unpadded
            red = GL.glReadPixels(0, 0, width, height, GL.GL_RED, GL.GL_UNSIGNED_BYTE)
            GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 4)  # GL's default, which pyrender's own read-backs assume
            GL.glEnable(GL.GL_DEPTH_TEST)
            return np.frombuffer(red, np.uint8).reshape(height, width)[::-1] > 0  # GL rows run up

        def depth_pass(self, primitives, view: np.ndarray, projection: np.ndarray) -> np.ndarray:
            """(H, W) float32, what pyrender's depth-only pass of the primitives returns (its framebuffer, state
            and read-back: linear depth between `DUMMY_PLANES`, 0 where nothing was drawn)."""
            self._configure_forward_pass_viewport(_DEPTH_ONLY | RenderFlags.OFFSCREEN)
            GL.glClearColor(1.0, 1.0, 1.0, 1.0)
            GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
            self._draw_primitives(primitives, view, projection)
            return self.linear_depth(self.window_depth(), *DUMMY_PLANES)

        def _draw_primitives(self, primitives, view: np.ndarray, projection: np.ndarray) -> None:
            if not primitives:
                return
            program = self._get_primitive_program(primitives[0], _DEPTH_ONLY, ProgramFlags.USE_MATERIAL)
            program._bind()
            program.set_uniform("V", view)
            program.set_uniform("P", projection)
            program.set_uniform("M", _IDENTITY)
            GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_FILL)
            for primitive in primitives:
                primitive._bind()
                if primitive.culled:
                    GL.glEnable(GL.GL_CULL_FACE)
                    GL.glCullFace(GL.GL_BACK)
                else:
                    GL.glDisable(GL.GL_CULL_FACE)
                GL.glDrawElements(primitive.mode, primitive.indices.size, GL.GL_UNSIGNED_INT, ctypes.c_void_p(0))
                primitive._unbind()
            program._unbind()

        def _cover_target(self, width: int, height: int):
            """The framebuffer of one R8 colour renderbuffer of this size, made on first use and kept among the
            _COVER_TARGETS most recently used (a library asset's passes come in four sizes)."""
            targets = self._cover_targets
            if (width, height) in targets:
                targets.move_to_end((width, height))
            else:
                if len(targets) >= _COVER_TARGETS:
                    framebuffer, renderbuffer = targets.popitem(last=False)[1]
                    GL.glDeleteFramebuffers(1, [framebuffer])
                    GL.glDeleteRenderbuffers(1, [renderbuffer])
                renderbuffer = GL.glGenRenderbuffers(1)
                GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, renderbuffer)
                GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_R8, width, height)
                framebuffer = GL.glGenFramebuffers(1)
                GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, framebuffer)
                GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER,
                                             renderbuffer)
                targets[width, height] = (framebuffer, renderbuffer)
            return targets[width, height][0]

    return DirectPassRenderer
