"""Depth-guided growth from one sketch (seed 000, chapter 3; digest 1.10-1.12), the geometry half.

In: silhouette maps (front depth01, gap, mask), trunk depth, colour trunk strokes and the input view's `Camera`
(network outputs, or ground-truth renders standing in for them). Out: a `Reconstruction` (method "sketch-depth"):
the grown `Skeleton`, its `TreeMesh`, the growth dictionary, stage timings and the intermediate maps.

Steps, each a plain function over arrays: `denoise_depth` (eq. 3.4-3.5), `backproject` (depth01 to world
points), `trace_trunk` (in `reconstruct.trunk_tracing`: breadth-first stroke tracing into a 3D main skeleton),
`CameraCrown` (the growth space between front and back depth seen through any camera), `geodesic_field`
(Dijkstra bins joined into a 2D attraction skeleton), then `from_sketch` revolves the field, grows from the main
skeleton and meshes.
"""
from __future__ import annotations

import copy
import time
from dataclasses import replace

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from renderers.camera import Camera
from species.colonization import GrowthSpace, MarkerSteering, grow_in_space, revolved_field, validate
from species.geometry.vectors import unit_vectors
from species.meshing import build_mesh
from species.presets import get_preset
from species.skeleton import Skeleton
from species.timing import StageTimer

from ._sketch_arrays import SketchError, check_camera, check_height, disc, image_array, metres
from .fit_sketch_depth import WINDOW_PAD, WINDOW_PX, fit_sketch_depth, offset_mask, settings_params
from .fit_budget import DEFAULT_FIT_EVALS, check_fit_evals
from .fitting import renderer_at
from .networks import as_image, colonization_species, photo_edges, predictor, sketch_maps
from .result import Reconstruction
from .trunk_tracing import stroke_labels, trace_trunk

__all__ = ["SketchError", "CameraCrown", "from_sketch", "from_maps", "backproject", "denoise_depth",
           "geodesic_field", "crown_maps", "DEFAULT_SPECIES", "DENOISE_EPSILON"]

DEFAULT_SPECIES = "sc_round_maple"  # a round crown with balanced allocation: the general-purpose default
DENOISE_EPSILON = 0.019             # thesis eq. 3.5
_REFERENCE_PX = 256                 # the thesis's image size; pixel constants below scale from it
_BIN_PX = 8.0                       # digest 1.12: geodesic bin width at 256 px
_CLOSE_PX = 3.0                     # crown closing radius at 256 px (joins the leaves of a sparse silhouette)


# ------------------------------------------------------------------------------------------------ depth
def backproject(depth01: np.ndarray, mask: np.ndarray, camera: Camera) -> np.ndarray:
    """(N, 3) float64 world points (metres) of the mask's pixels (row-major order) at their depth01.

    depth01 : (H, W) float in [0, 1] between the camera's near and far planes (`Camera.depth01`'s inverse);
    mask    : (H, W) bool or 0/1, the pixels to lift. Pixel (row i, column j) is (u, v) = (j, i).
    """
    depth01 = image_array(depth01, "depth01", (0,)).astype(np.float64)
    mask = image_array(mask, "mask", (0,)).astype(bool)
    if mask.shape != depth01.shape:
        raise SketchError(f"mask {mask.shape} and depth01 {depth01.shape} must have one shape")
    check_camera(camera, depth01.shape)
    rows, cols = np.nonzero(mask)
    return camera.unproject(np.stack([cols, rows], axis=1), metres(camera, depth01[rows, cols]))


_RING = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if (dy, dx) != (0, 0)]  # N(p): 5x5 minus centre


def _shifted(image: np.ndarray, fill) -> np.ndarray:
    """(24, H, W): image[p + offset] for every offset of the 5x5 ring, `fill` outside the image."""
    h, w = image.shape
    padded = np.pad(image, 2, constant_values=fill)
    return np.stack([padded[2 + dy:2 + dy + h, 2 + dx:2 + dx + w] for dy, dx in _RING])


def denoise_depth(depth: np.ndarray, mask: np.ndarray, epsilon: float = DENOISE_EPSILON
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Seed 000's boundary denoising (eq. 3.4-3.5, digest 1.10): returns (depth, mask), cleaned.

    depth : (H, W) or (H, W, C) float, e.g. depth01 or (front, gap); each channel is cleaned on its own.
    mask  : (H, W) bool foreground. N(p) = the foreground pixels of p's 5x5 window minus p.
    d(p) = mean over N(p) of |depth(p) - depth(i)|; a boundary pixel (removed by a 3x3 erosion of the mask) is
    noise when mean over N(p) of (d(i) - d(p))^2 > epsilon (eq. 3.5's self-referring d_avg read as p's own d).
    A noisy pixel takes the mean depth of its clean neighbours; one with none leaves the mask.
    """
    depth = np.asarray(depth, np.float64)
    if depth.ndim not in (2, 3):
        raise SketchError(f"depth has shape {depth.shape}: allowed (H, W) or (H, W, C)")
    mask = image_array(mask, "mask", (0,)).astype(bool)
    if mask.shape != depth.shape[:2]:
        raise SketchError(f"mask {mask.shape} and depth {depth.shape} must share (H, W)")
    if not epsilon >= 0:
        raise SketchError(f"epsilon {epsilon} must be >= 0")
    planes = depth[..., None] if depth.ndim == 2 else depth
    border = mask & ~ndimage.binary_erosion(mask, np.ones((3, 3), bool), border_value=0)
    near = _shifted(mask, False)                                   # (24, H, W) foreground neighbours
    count = near.sum(axis=0)
    out, keep = planes.copy(), mask.copy()
    for k in range(planes.shape[2]):  # a channel or two
        values = np.where(mask, planes[..., k], 0.0)
        around = _shifted(values, 0.0)
        spread = np.where(near, np.abs(around - values), 0.0).sum(axis=0) / np.maximum(count, 1)
        variance = (np.where(near, (_shifted(spread, 0.0) - spread) ** 2, 0.0).sum(axis=0)
                    / np.maximum(count, 1))
        noisy = border & (variance > epsilon)
        clean = near & ~_shifted(noisy, True)
        n_clean = clean.sum(axis=0)
        mean = np.where(clean, around, 0.0).sum(axis=0) / np.maximum(n_clean, 1)
        out[..., k] = np.where(noisy, mean, planes[..., k])
        keep &= ~(noisy & (n_clean == 0))
    out = out[..., 0] if depth.ndim == 2 else out
    return out, keep


# ------------------------------------------------------------------------------------------------ crown
class CameraCrown(GrowthSpace):
    """The crown between front and back depth maps seen through any camera (DepthMapCrown for any `Camera`).

    front, back : (H, W) float depth01 of the camera; mask : (H, W) bool crown pixels. Points live in an output
    frame: world = origin + points / scale (metres), so growth can run with the base at the origin and the
    sketch's metric scale. A point is inside when it projects (nearest pixel centre) onto a mask pixel with its
    depth01 between front and back there. Exact for perspective and orthographic cameras alike.
    """

    def __init__(self, front: np.ndarray, back: np.ndarray, mask: np.ndarray, camera: Camera,
                 origin=(0.0, 0.0, 0.0), scale: float = 1.0):
        self.front = image_array(front, "front", (0,)).astype(np.float64)
        self.back = image_array(back, "back", (0,)).astype(np.float64)
        self.mask = image_array(mask, "mask", (0,)).astype(bool) & (self.back >= self.front)
        if self.front.shape != self.back.shape or self.mask.shape != self.front.shape:
            raise SketchError(f"front {self.front.shape}, back {self.back.shape} and mask {mask.shape} must "
                              "share one shape")
        self.camera = check_camera(camera, self.front.shape)
        if not self.mask.any():
            raise SketchError("the crown has no pixel with back depth at or behind front depth")
        if not scale > 0:
            raise SketchError(f"scale {scale} must be > 0")
        self.origin, self.scale = np.asarray(origin, np.float64).reshape(3), float(scale)
        ends = np.concatenate([backproject(self.front, self.mask, camera), backproject(self.back, self.mask, camera)])
        ends = (ends - self.origin) * self.scale
        pad = self.scale * float(camera.metres_per_pixel(camera.far))
        self.bounds = np.stack([ends.min(axis=0) - pad, ends.max(axis=0) + pad])

    def _contains(self, points: np.ndarray) -> np.ndarray:
        pixels, z = self.camera.project(self.origin + points / self.scale)
        col, row = np.rint(pixels[:, 0]), np.rint(pixels[:, 1])
        ok = (z > 0) & (col >= 0) & (col < self.camera.width) & (row >= 0) & (row < self.camera.height)
        col, row = np.where(ok, col, 0).astype(np.int64), np.where(ok, row, 0).astype(np.int64)
        d = (z - self.camera.near) / (self.camera.far - self.camera.near)
        return ok & self.mask[row, col] & (d >= self.front[row, col]) & (d <= self.back[row, col])

    def __repr__(self) -> str:
        return f"CameraCrown(pixels={int(self.mask.sum())}, camera={self.camera.name!r})"


def crown_maps(front: np.ndarray, back: np.ndarray, mask: np.ndarray, axis_px: tuple[float, float],
               axis_depth01: float, camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The crown's (front, back, mask) from a silhouette's: the mask closed and its holes filled (a crown of
    scattered leaves is one region), front and back filled from the nearest foreground pixel, and each pixel's
    span widened to at least the crown revolved about the trunk axis (axis_px = (u, v) of its base,
    axis_depth01 its depth): a row whose crown reaches R px from the axis is 2 sqrt(R^2 - x^2) px deep at x px.
    Our choice where the thesis is silent: the thin spans of a leafy silhouette leave no room to grow."""
    scale = max(mask.shape) / _REFERENCE_PX
    closed = ndimage.binary_closing(np.pad(mask, 8), disc(max(1.0, _CLOSE_PX * scale)))[8:-8, 8:-8]
    crown = ndimage.binary_fill_holes(closed | mask)
    _, (near_row, near_col) = ndimage.distance_transform_edt(~mask, return_indices=True)
    front_f, back_f = front[near_row, near_col], back[near_row, near_col]
    offset = np.abs(np.arange(mask.shape[1]) - axis_px[0])[None, :]
    reach = np.where(crown, offset, 0.0).max(axis=1, keepdims=True)
    span_px = 2 * np.sqrt(np.maximum(reach ** 2 - offset ** 2, 0.0))
    per_px = float(camera.metres_per_pixel(metres(camera, axis_depth01))) / (camera.far - camera.near)
    half = 0.5 * span_px * per_px
    top = 1.0 - 1e-6
    front_c = np.clip(np.minimum(front_f, axis_depth01 - half), 0.0, top)
    back_c = np.clip(np.maximum(back_f, axis_depth01 + half), 0.0, top)
    return np.where(crown, front_c, 1.0), np.where(crown, back_c, 1.0), crown


# ------------------------------------------------------------------------------------------------ field
_NEIGHBOURS = ((0, 1, 1.0), (1, 0, 1.0), (1, 1, np.sqrt(2.0)), (1, -1, np.sqrt(2.0)))


def geodesic_field(mask: np.ndarray, root_px: tuple[int, int], bin_px: float = _BIN_PX
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The 2D attraction field of digest 1.12: (directions (H, W, 2) image-plane (x right, z up) unit or 0,
    geodesic distance (H, W) px, inf off the region).

    Dijkstra from root_px = (u, v) over the 8-connected mask; pixels binned by distance (bin_px wide), each bin
    split into 8-connected clusters; a cluster hangs from the cluster of its nearest pixel's predecessor, and
    its pixels take the mean of its incoming edge and its outgoing edges between cluster centres.
    """
    mask = np.asarray(mask, bool).copy()
    h, w = mask.shape
    mask[root_px[1], root_px[0]] = True
    index = np.full((h, w), -1, np.int64)
    rows, cols = np.nonzero(mask)
    index[rows, cols] = np.arange(len(rows))
    a, b, cost = [], [], []
    for dy, dx, length in _NEIGHBOURS:  # four offsets, each vectorized over the image
        src = index[max(0, -dy):h - max(0, dy), max(0, -dx):w - max(0, dx)]
        dst = index[max(0, dy):h - max(0, -dy) or None, max(0, dx):w - max(0, -dx) or None]
        both = (src >= 0) & (dst >= 0)
        a.append(src[both]), b.append(dst[both]), cost.append(np.full(int(both.sum()), length))
    a, b, cost = np.concatenate(a), np.concatenate(b), np.concatenate(cost)
    n = len(rows)
    graph = coo_matrix((cost, (a, b)), shape=(n, n)).tocsr()
    distance, predecessor = dijkstra(graph, directed=False, indices=int(index[root_px[1], root_px[0]]),
                                     return_predecessors=True)
    reached = np.isfinite(distance)
    bins = np.where(reached, np.floor(distance / bin_px), -1).astype(np.int64)
    same = (bins[a] == bins[b]) & reached[a]
    _, cluster = connected_components(coo_matrix((np.ones(int(same.sum())), (a[same], b[same])), shape=(n, n)),
                                      directed=False)
    _, cluster = np.unique(cluster, return_inverse=True)
    m = int(cluster.max()) + 1
    counts = np.bincount(cluster, minlength=m)
    centre = np.stack([np.bincount(cluster, cols, m), np.bincount(cluster, rows, m)], axis=1) / counts[:, None]
    by_distance = np.lexsort((np.where(reached, distance, np.inf), cluster))
    first = by_distance[np.r_[True, cluster[by_distance][1:] != cluster[by_distance][:-1]]]
    before = predecessor[first]
    parent = np.where(before >= 0, cluster[np.maximum(before, 0)], -1)
    parent[~reached[first]] = -1
    has_parent = parent >= 0
    edge = np.zeros((m, 2))
    edge[has_parent] = unit_vectors(np.pad(centre[has_parent] - centre[parent[has_parent]], ((0, 0), (0, 1))))[:, :2]
    total = edge.copy()
    links = np.bincount(parent[has_parent], minlength=m) + has_parent
    for d in range(2):
        total[:, d] += np.bincount(parent[has_parent], edge[has_parent, d], m)
    mean = total / np.maximum(links, 1)[:, None]
    flow = unit_vectors(np.pad(mean * [1.0, -1.0], ((0, 0), (0, 1))))[:, :2]  # image v down -> z up
    directions = np.zeros((h, w, 2))
    directions[rows, cols] = np.where(reached[:, None], flow[cluster], 0.0)
    geodesic = np.full((h, w), np.inf)
    geodesic[rows, cols] = distance
    return directions, geodesic


def _axis_extent(camera: Camera, base: np.ndarray, scale: float) -> tuple[float, float, float, float]:
    """The image's (x0, x1, z0, z1) in the output frame on the vertical plane through the base that faces the
    camera: the extent `revolved_field` reads a 2D field with (exact for level views, near for tilted ones)."""
    forward = camera.world_to_camera[2, :3].copy()
    forward[2] = 0.0
    if np.linalg.norm(forward) < 1e-9:  # looking straight down: any vertical plane will do
        forward = np.array([0.0, 1.0, 0.0])
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    pixel, _ = camera.project(base[None])
    u0, v0 = pixel[0]
    edges = np.array([[-0.5, v0], [camera.width - 0.5, v0], [u0, camera.height - 0.5], [u0, -0.5]])
    nearby = camera.unproject(edges, np.full(4, camera.near))
    faraway = camera.unproject(edges, np.full(4, camera.far))
    t = ((base - nearby) @ forward) / np.where(np.abs((faraway - nearby) @ forward) > 1e-12,
                                               (faraway - nearby) @ forward, 1e-12)
    on_plane = nearby + t[:, None] * (faraway - nearby) - base
    x0, x1 = on_plane[:2] @ right * scale  # image right is forward x up, as in every Camera
    z0, z1 = on_plane[2:, 2] * scale
    return float(x0), float(x1), float(z0), float(z1)


# ------------------------------------------------------------------------------------------------ growth
def _thinned(skeleton: Skeleton, spacing: float) -> Skeleton:
    """The skeleton with nodes kept about every `spacing` metres along each branch, and always its root, branch
    ends, junctions and branch starts; each kept node hangs from its nearest kept ancestor."""
    parent = skeleton.parent.astype(np.int64)
    arc = np.zeros(len(skeleton))
    for path in skeleton.branch_paths:  # one cumulative sum per branch, from its junction
        arc[path[1:]] = np.cumsum(skeleton.segment_lengths[path[1:]])
    step = np.floor(arc / spacing)
    keep = step != step[np.maximum(parent, 0)]
    keep[skeleton.n_children != 1] = True
    keep[skeleton.branch_starts] = True
    keep[0] = True
    up = np.where(keep, np.arange(len(skeleton)), parent)
    while True:  # nearest kept ancestor by repeated gathers
        nxt = np.where(keep[np.maximum(up, 0)] | (up < 0), up, parent[np.maximum(up, 0)])
        if np.array_equal(nxt, up):
            break
        up = nxt
    ids = np.flatnonzero(keep)
    new = np.full(len(skeleton), -1, np.int64)
    new[ids] = np.arange(len(ids))
    anc = np.where(parent[ids] >= 0, up[np.maximum(parent[ids], 0)], -1)
    return Skeleton(skeleton.positions[ids], np.where(anc >= 0, new[np.maximum(anc, 0)], -1),
                    skeleton.radius[ids], skeleton.order[ids])


def _colonization_params(species: str, rng: np.random.Generator) -> dict:
    preset = get_preset(species)
    if preset.generator != "colonization":
        raise SketchError(f"species {species!r} is a {preset.generator} preset: allowed a colonization preset "
                          f"(sc_*), default {DEFAULT_SPECIES!r}")
    return validate(preset.sample(rng))


def from_sketch(sketch, strokes, *, models=None, species: str | None = None, height: float | None = None,
                rng: np.random.Generator, photo: bool = False, silhouette_net=None, trunk_net=None,
                sketchnet=None, fit_evals: int = DEFAULT_FIT_EVALS, renderer=None) -> Reconstruction:
    """A tree from a drawing: the silhouette network reads `sketch` (black edges on white, any size; with
    `photo`, a photo whose blurred Canny edges are the sketch), the trunk network `strokes` (colour trunk strokes
    on the same page), and `from_maps` grows the tree in the drawing's view (`reconstruct.networks`).

    models : a registry (its champions) or None for the shipped defaults; the *_net arguments: loaded predictors.
    species : a colonization preset, "auto" (TreeSketchNet reads the species from the sketch, mapped by
              `networks.SPECIES_TO_COLONIZATION`) or None (DEFAULT_SPECIES). height, rng : as `from_maps`.
    fit_evals : candidate trees the fit to the drawing may grow and redraw (`from_maps`'s fit_to: the sketch's
              ink in the silhouette network's window); 0 grows the networks' guess as it is.
    renderer : a `renderers.ViewRenderer` to redraw candidates with (one is made when fitting without it).
    Maps add "sketch" (the silhouette network's input) and "trunk_depth", "strokes", "silhouette" (in its
    window); timings add "networks".
    """

    start = time.perf_counter()
    if not isinstance(rng, np.random.Generator):
        raise SketchError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    fit_evals = check_fit_evals(fit_evals)
    sketch = photo_edges(sketch) if photo else as_image(sketch, "sketch")
    silhouette_net = silhouette_net or predictor("pix2pix-silhouette", models)
    found = sketch_maps(sketch, strokes, silhouette_net=silhouette_net,
                        trunk_net=trunk_net or predictor("pix2pix-trunk", models))
    chosen = DEFAULT_SPECIES if species is None else species
    if species == "auto":
        chosen = colonization_species((sketchnet or predictor("sketchnet", models)).predict(sketch)["species"])
    networks = time.perf_counter() - start
    ink = found.sketch_input[0] > 0.5 if fit_evals else None  # the drawing over the maps' window
    result = from_maps(found.silhouette, found.trunk_depth, found.strokes, found.camera, species=chosen,
                       height=height, rng=rng, fit_to=ink, fit_evals=fit_evals, renderer=renderer)
    timings = {**result.timings, "networks": networks}
    timings["total"] += networks
    return replace(result, timings=timings, maps={**result.maps, "sketch": found.sketch_input[0],
                                                  "trunk_depth": found.trunk_depth, "strokes": found.strokes,
                                                  "silhouette": found.silhouette})


def from_maps(silhouette_maps: np.ndarray, trunk_maps: np.ndarray, strokes: np.ndarray, camera: Camera, *,
              species: str = DEFAULT_SPECIES, height: float | None = None,
              rng: np.random.Generator, fit_to: np.ndarray | None = None, fit_evals: int = 0,
              renderer=None) -> Reconstruction:
    """Grow a tree that fills a sketch's crown from its traced main branches (seed 000 chapter 3), given the depth
    networks' maps (or ground-truth renders standing in for them).

    silhouette_maps : (H, W, 3) float in [0, 1]: front depth01, front-to-back gap, mask (the renderers'
                      "silhouette_envelope" output, what the silhouette network predicts, or the per-leaf
                      "silhouette"); mask < 0.5 is background.
    trunk_maps      : (H, W) float trunk depth01, 1 = no stroke (the "trunk_depth" output or prediction).
    strokes         : (H, W, 3) uint8 colour trunk strokes on white (see `trace_trunk`).
    camera          : the input view's Camera; the maps are its size.
    species         : a colonization preset (DEFAULT_SPECIES = "sc_round_maple" unless told).
    height          : metres from the trunk base to the crown top; default the preset's draw.
    rng             : draws the preset's parameters, then growth; the same state gives the same bytes.
    The tree's base is the lowest stroke point, moved to the origin; the sketch is scaled to `height`. The
    preset's internode length is height / (crown_base + crown_height), so its IL-sized settings keep their sense.
    Maps: "front", "back", "crown_mask" (H, W) (the growth space's), "geodesic" (H, W) px,
    "directions" (H, W, 2), "trunk_px" (K, 2) (u, v) of the traced main skeleton's nodes, "main_skeleton"
    (G, 3) float32 metres, the guide grown from (the traced nodes about one internode apart: the tree's first G).
    fit_to, fit_evals, renderer : with the drawing's ink in `camera` ((H, W) bool) and a budget of evaluations
                      > 0, the crown envelope and growth settings are fitted so the tree's filled outline in
                      `camera` matches the ink's (`reconstruct.fit_sketch_depth`; the main skeleton stays as
                      traced), redrawn by `renderer` (one is made without it); maps add "fit" (a
                      `reconstruct.fitting.FitRecord`), timings "fit". Without them the guess is grown as it is.
    """
    timer = StageTimer()
    lap = timer.lap
    if not isinstance(rng, np.random.Generator):
        raise SketchError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    silhouette = image_array(silhouette_maps, "silhouette_maps", (3,)).astype(np.float64)
    trunk_depth = image_array(trunk_maps, "trunk_maps", (0,)).astype(np.float64)
    check_camera(camera, silhouette.shape[:2])
    check_height(height, "the preset's")
    fit_evals = check_fit_evals(fit_evals)
    if fit_to is not None:
        fit_to = image_array(fit_to, "fit_to", (0,)).astype(bool)
        if fit_to.shape != silhouette.shape[:2]:
            raise SketchError(f"fit_to {fit_to.shape} and the maps {silhouette.shape[:2]} must share (H, W)")
    params = _colonization_params(species, rng)
    height = float(params["height"] if height is None else height)
    params["height"] = height

    mask = silhouette[..., 2] >= 0.5
    if not mask.any():
        raise SketchError("the silhouette is blank (no foreground pixel): allowed a sketch with a tree on it")
    cleaned, mask = denoise_depth(silhouette[..., :2], mask)
    front, gap = cleaned[..., 0], cleaned[..., 1]
    back = np.minimum(front + gap, 1.0 - 1e-6)
    lap("denoise")

    main = trace_trunk(strokes, trunk_depth, camera)
    base = main.positions[0].astype(np.float64)
    lap("trunk")

    base_px, base_depth = camera.project(base[None])
    base_u, base_v = float(base_px[0, 0]), float(base_px[0, 1])
    axis01 = float((base_depth[0] - camera.near) / (camera.far - camera.near))
    front_c, back_c, crown_mask = crown_maps(front, back, mask, (base_u, base_v), axis01, camera)
    _, _, bottom_z, top_z = _axis_extent(camera, base, 1.0)  # metres above the base, image bottom and top edges
    # The tree's top is the highest thing drawn: a bare leader's strokes can stand above the crown.
    drawn = crown_mask | (stroke_labels(strokes)[0] >= 0)
    top_row = int(np.flatnonzero(drawn.any(axis=1))[0])
    tree_height = top_z - top_row / camera.height * (top_z - bottom_z)  # to the top edge of the crown's top row
    if not tree_height > 0:
        raise SketchError("the crown lies below the lowest trunk stroke: allowed strokes that start at the "
                          "trunk base, below the crown")
    scale = height / tree_height
    crown = CameraCrown(front_c, back_c, crown_mask, camera, origin=base, scale=scale)
    lap("crown")

    region = drawn
    root = (int(np.clip(np.rint(base_u), 0, camera.width - 1)), int(np.clip(np.rint(base_v), 0, camera.height - 1)))
    directions, geodesic = geodesic_field(region, root, _BIN_PX * max(camera.width, camera.height) / _REFERENCE_PX)
    steering = MarkerSteering(attraction=revolved_field(directions, _axis_extent(camera, base, scale)))
    lap("field")

    il = height / (params["crown_base"] + params["crown_height"])
    guide_positions = (main.positions.astype(np.float64) - base) * scale
    guide = Skeleton(guide_positions, main.parent, main.radius * scale, main.order)
    guide = _thinned(guide, il)
    fitting = fit_to is not None and fit_evals > 0
    growth_rng = copy.deepcopy(rng) if fitting else None  # every candidate grows from the guess's draws
    skeleton = grow_in_space(params, rng, space=crown, internode_length=il, guide=guide, guide_buds="all",
                             steering=steering)
    lap("growth")
    mesh = build_mesh(skeleton, params)
    lap("mesh")
    maps = {}
    if fitting:
        def grow(settings: dict[str, float]):
            grown = settings_params(params, settings)
            offset = int(round(settings["envelope_px"] * max(camera.width, camera.height) / _REFERENCE_PX))
            space = crown if offset == 0 else CameraCrown(
                *crown_maps(front, back, offset_mask(mask, offset), (base_u, base_v), axis01, camera), camera,
                origin=base, scale=scale)
            tree = grow_in_space(grown, copy.deepcopy(growth_rng), space=space, internode_length=il, guide=guide,
                                 guide_buds="all", steering=steering)
            return grown, tree, build_mesh(tree, grown)

        with renderer_at(renderer, WINDOW_PX + 2 * WINDOW_PAD) as drawing:
            fit = fit_sketch_depth(grow, (params, skeleton, mesh), fit_to, fit_evals, copy.deepcopy(growth_rng),
                                   drawing, _in_growth_frame(camera, base, scale, WINDOW_PX + 2 * WINDOW_PAD,
                                                             (WINDOW_PX + 2 * WINDOW_PAD) / WINDOW_PX))
        params, skeleton, mesh, maps["fit"] = fit.params, fit.skeleton, fit.mesh, fit.record
        lap("fit")
    timings = {**timer.seconds, "total": sum(timer.seconds.values())}
    trunk_px, _ = camera.project(main.positions)
    maps.update({"front": front_c.astype(np.float32), "back": back_c.astype(np.float32), "crown_mask": crown_mask,
                 "geodesic": geodesic.astype(np.float32), "directions": directions.astype(np.float32),
                 "trunk_px": trunk_px.astype(np.float32), "main_skeleton": guide.positions.copy()})
    return Reconstruction("sketch-depth", skeleton, mesh, params, timings, maps)


def _in_growth_frame(camera: Camera, base: np.ndarray, scale: float, size: int, zoom_out: float = 1.25) -> Camera:
    """`camera` seen from the grown tree's frame (points = (world - base) * scale), `size` px square and its view
    widened `zoom_out` times about its centre, so leaves past the drawing's window stay in the picture."""
    world_to_camera = camera.world_to_camera.copy()
    world_to_camera[:3, 3] = scale * (world_to_camera[:3, :3] @ base + world_to_camera[:3, 3])
    k = np.array(camera.K, np.float64)
    pixel = np.diag([size / camera.width, size / camera.height, 1.0])
    intrinsics = pixel @ k
    intrinsics[:2, 2] = (k[:2, 2] + 0.5) * np.diag(pixel)[:2] - 0.5
    per_unit = 1.0 / scale if camera.is_orthographic else 1.0
    intrinsics[0, 0] *= per_unit / zoom_out
    intrinsics[1, 1] *= per_unit / zoom_out
    return Camera(size, size, intrinsics, world_to_camera, camera.projection, camera.near * scale,
                  camera.far * scale, camera.ortho_half_width * scale * zoom_out,
                  camera.ortho_half_height * scale * zoom_out, name=camera.name)
