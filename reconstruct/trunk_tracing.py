"""Trunk tracing (thesis 3.3, digest 1.11): colour trunk strokes and their depth into a 3D main skeleton.

`stroke_labels` snaps drawn colours to the palette and joins each colour's pieces; `trace_trunk` walks the strokes
breadth-first from the lowest point into nodes, splits them into branches and lifts them with the trunk depth.
"""
from __future__ import annotations

from collections import deque

import numpy as np
from scipy import ndimage

from renderers.camera import Camera
from renderers.strokes import PALETTE, STROKE_WIDTH_PX
from species.skeleton import Skeleton

from ._sketch_arrays import SketchError, check_camera, disc, image_array, metres

__all__ = ["trace_trunk", "stroke_labels", "TRACE_STEP_PX", "TRACE_RADIUS_PX"]

TRACE_STEP_PX = 4.0                 # thesis 3.3: probe step of the trunk tracing
TRACE_RADIUS_PX = 4.0               # and the radius whose stroke pixels' centroid is a node
_CONSUMED_PX = 3.5                  # stroke pixels this near a node are traced (below the step, so probes land)
_MERGE_GAP_PX = 6                   # same-colour stroke pieces this close are one branch (a crossing hides ~4 px)
_MIN_BRANCH_NODES = 3               # a side chain of fewer traced nodes is a spur of a wide stroke, dropped
_MIN_SATURATION, _MIN_VALUE = 0.35, 0.25  # below either, a pixel is paper, pencil or ink, not a colour stroke


def stroke_labels(strokes_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Colour strokes to branch pieces: labels (H, W) int64 (-1 off the strokes) and each label's palette index.

    A pixel is a stroke pixel when it is saturated and bright enough; its colour snaps to the palette entry of
    the nearest hue (the 12 entries are 30 deg apart, and paper, anti-aliasing and scanning change a drawn
    colour's saturation and value far more than its hue). Pixels of one palette index within _MERGE_GAP_PX of
    each other are one piece, so a branch hidden for a stroke width under a crossing stays one branch.
    """
    rgb = image_array(strokes_rgb, "strokes", (3, 4))[..., :3].astype(np.float64)
    if rgb.max(initial=0) > 1.0:
        rgb = rgb / 255.0
    top, low = rgb.max(axis=2), rgb.min(axis=2)
    chroma = top - low
    stroke = (top >= _MIN_VALUE) & (chroma >= _MIN_SATURATION * np.maximum(top, 1e-9))
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    hue = np.degrees(np.arctan2(np.sqrt(3.0) * (g - b), 2 * r - g - b)) % 360.0
    colour = np.rint(hue / (360.0 / len(PALETTE))).astype(np.int64) % len(PALETTE)
    labels = np.full(rgb.shape[:2], -1, np.int64)
    palette_of = []
    merge_disc = disc(_MERGE_GAP_PX / 2)
    for index in range(len(PALETTE)):  # twelve colours
        pixels = stroke & (colour == index)
        if not pixels.any():
            continue
        pieces, n = ndimage.label(ndimage.binary_dilation(pixels, merge_disc), np.ones((3, 3), bool))
        labels[pixels] = pieces[pixels] - 1 + len(palette_of)
        palette_of.extend([index] * n)
    # Pieces smaller than a stroke-width square are specks (noise, a colour fringe), not strokes.
    sizes = np.bincount(labels[labels >= 0], minlength=len(palette_of) + 1)
    labels[(labels >= 0) & (sizes[np.maximum(labels, 0)] < STROKE_WIDTH_PX ** 2)] = -1
    used, labels_flat = np.unique(labels[labels >= 0], return_inverse=True)
    out = np.full_like(labels, -1)
    out[labels >= 0] = labels_flat
    return out, np.asarray(palette_of, np.int64)[used]


def _window(shape, centre, radius):
    """Row and column slices of the square window of `radius` around centre (u, v), clipped to the image."""
    u, v = centre
    r = int(np.ceil(radius))
    r0, c0 = max(int(np.floor(v)) - r, 0), max(int(np.floor(u)) - r, 0)
    return slice(r0, min(int(np.ceil(v)) + r + 1, shape[0])), slice(c0, min(int(np.ceil(u)) + r + 1, shape[1]))


def _trace_nodes(labels: np.ndarray, depth01: np.ndarray):
    """Breadth-first tracing (thesis 3.3): node pixels (K, 2) (u, v), labels (K,), BFS parents (K,), depth01 (K,).

    From the lowest stroke pixel, each node probes the 8 compass directions TRACE_STEP_PX away; a probe on an
    untraced stroke pixel makes a node at the centroid of that piece's pixels within TRACE_RADIUS_PX. A loop
    over nodes (a few hundred), each touching a 9x9 window: the trace is sequential by nature.
    """
    h, w = labels.shape
    rows, cols = np.nonzero(labels >= 0)
    yy, xx = np.mgrid[0:h, 0:w]
    consumed = np.zeros((h, w), bool)
    valid_depth = depth01 < 1.0
    compass = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1]], np.float64)
    probes = compass / np.linalg.norm(compass, axis=1, keepdims=True) * TRACE_STEP_PX
    lowest = np.flatnonzero(rows == rows.max())
    start = lowest[np.argmin(np.abs(cols[lowest] - np.median(cols[lowest])))]
    nodes, node_label, node_parent, node_depth = [], [], [], []

    def add(pixel, parent):
        label = labels[pixel[1], pixel[0]]
        rs, cs = _window((h, w), pixel, TRACE_RADIUS_PX)
        near = ((xx[rs, cs] - pixel[0]) ** 2 + (yy[rs, cs] - pixel[1]) ** 2 <= TRACE_RADIUS_PX ** 2)
        near &= labels[rs, cs] == label
        centre = np.array([xx[rs, cs][near].mean(), yy[rs, cs][near].mean()])
        depths = depth01[rs, cs][near & valid_depth[rs, cs]]
        depth = float(np.median(depths)) if len(depths) else (node_depth[parent] if parent >= 0 else np.nan)
        rs, cs = _window((h, w), centre, _CONSUMED_PX)
        consumed[rs, cs] |= ((xx[rs, cs] - centre[0]) ** 2 + (yy[rs, cs] - centre[1]) ** 2 <= _CONSUMED_PX ** 2)
        nodes.append(centre), node_label.append(label), node_parent.append(parent), node_depth.append(depth)

    add((int(cols[start]), int(rows[start])), -1)
    queue = deque([0])
    while True:
        while queue:
            k = queue.popleft()
            hits = np.rint(nodes[k] + probes).astype(np.int64)
            inside = (hits[:, 0] >= 0) & (hits[:, 0] < w) & (hits[:, 1] >= 0) & (hits[:, 1] < h)
            for u, v in hits[inside]:
                if labels[v, u] >= 0 and not consumed[v, u]:
                    add((int(u), int(v)), k)
                    queue.append(len(nodes) - 1)
        # A branch leaving a stroke at a shallow angle, or touching it only where the probes fell on traced
        # pixels, is missed by the probes: go on from the untraced stroke nearest the traced nodes.
        restart = _untraced_start(labels, consumed, np.asarray(nodes))
        if restart is None:
            break
        pixel, parent = restart
        add(pixel, parent)
        queue.append(len(nodes) - 1)
    depth = np.asarray(node_depth, np.float64)
    if np.isnan(depth).all():
        raise SketchError("the trunk depth map has no stroke depth (every pixel under the strokes is 1 = "
                          "background): allowed a trunk depth map that covers the strokes")
    return (np.asarray(nodes), np.asarray(node_label, np.int64), np.asarray(node_parent, np.int64),
            np.where(np.isnan(depth), np.nanmedian(depth), depth))


def _untraced_start(labels: np.ndarray, consumed: np.ndarray, nodes: np.ndarray):
    """((u, v), nearest node) where tracing goes on: the pixel, of all untraced stroke pieces long enough to be a
    branch (_MIN_BRANCH_NODES probe steps), nearest to a traced node; None when no such piece is left."""
    untraced = (labels >= 0) & ~consumed
    pieces, n = ndimage.label(untraced, np.ones((3, 3), bool))
    if n == 0:
        return None
    boxes = ndimage.find_objects(pieces)
    reach = np.array([max(b[0].stop - b[0].start, b[1].stop - b[1].start) for b in boxes])
    long_enough = np.flatnonzero(reach >= _MIN_BRANCH_NODES * TRACE_STEP_PX) + 1
    if long_enough.size == 0:
        return None
    rows, cols = np.nonzero(np.isin(pieces, long_enough))
    offsets = (cols[:, None] - nodes[None, :, 0]) ** 2 + (rows[:, None] - nodes[None, :, 1]) ** 2
    pixel, node = np.unravel_index(np.argmin(offsets), offsets.shape)
    return (int(cols[pixel]), int(rows[pixel])), int(node)


def _branches(pixels: np.ndarray, label: np.ndarray, bfs_parent: np.ndarray) -> tuple[list[np.ndarray], list[int]]:
    """Traced nodes into branches: node index paths, and each branch's parent node (-1 for the trunk).

    Within a label a node hangs from its tracing parent when that is of the label, else from the nearest earlier
    node of the label (a piece re-entered across a crossing). Each label's tree is split into its longest path
    from its first node, then its side chains; chains of fewer than _MIN_BRANCH_NODES nodes (spurs of a wide
    stroke, specks of a stray colour) are dropped, except the trunk. A branch's first node hangs from its side
    chain's node or else from the nearest node of a branch found before it.
    """
    k = len(pixels)
    inner = np.full(k, -1, np.int64)
    for i in range(1, k):  # nodes in discovery order; parents come first
        same = np.flatnonzero(label[:i] == label[i])
        if not len(same):
            continue
        p = bfs_parent[i]
        inner[i] = p if label[p] == label[i] else same[np.argmin(((pixels[same] - pixels[i]) ** 2).sum(axis=1))]
    children = [[] for _ in range(k)]
    for i in range(k):
        if inner[i] >= 0:
            children[inner[i]].append(i)
    reach = np.ones(k, np.int64)  # nodes on the longest chain down from each node, itself included
    for i in range(k - 1, -1, -1):
        if children[i]:
            reach[i] = 1 + max(reach[c] for c in children[i])
    paths, starts = [], deque(np.flatnonzero(inner < 0))
    while starts:
        node = int(starts.popleft())
        path = [node]
        while children[path[-1]]:
            kids = children[path[-1]]
            best = max(kids, key=lambda c: reach[c])
            starts.extend(c for c in kids if c != best)
            path.append(best)
        paths.append(np.asarray(path))
    paths.sort(key=lambda p: p[0])  # discovery order of the first node: the trunk first
    paths = paths[:1] + [p for p in paths[1:] if len(p) >= _MIN_BRANCH_NODES]
    parents, placed = [-1], np.zeros(k, bool)
    placed[paths[0]] = True
    for path in paths[1:]:
        parent = inner[path[0]]
        if parent < 0 or not placed[parent]:
            earlier = np.flatnonzero(placed)
            parent = earlier[np.argmin(((pixels[earlier] - pixels[path[0]]) ** 2).sum(axis=1))]
        parents.append(int(parent))
        placed[path] = True
    return paths, parents


def trace_trunk(strokes_rgb: np.ndarray, trunk_depth: np.ndarray, camera: Camera) -> Skeleton:
    """The 3D main skeleton of colour trunk strokes (thesis 3.3, digest 1.11), in the camera's world (metres).

    strokes_rgb : (H, W, 3) uint8 (or (H, W, 4), alpha ignored), white paper, one palette colour per branch.
    trunk_depth : (H, W) float depth01 of the strokes, 1 = no stroke (the trunk network's output).
    Node 0 is the lowest stroke point; order = branch level (trunk 0); radius = one pixel in metres.
    """
    labels, _ = stroke_labels(strokes_rgb)
    trunk_depth = image_array(trunk_depth, "trunk_depth", (0,)).astype(np.float64)
    if trunk_depth.shape != labels.shape:
        raise SketchError(f"trunk_depth {trunk_depth.shape} and strokes {labels.shape} must share (H, W)")
    check_camera(camera, labels.shape)
    if not (labels >= 0).any():
        raise SketchError("the stroke image has no trunk stroke: draw the trunk and main branches in palette "
                          "colours (saturated, one colour per branch, trunk first) on white")
    pixels, label, bfs_parent, depth = _trace_nodes(labels, trunk_depth)
    paths, branch_parent = _branches(pixels, label, bfs_parent)
    nodes = np.concatenate(paths)
    new_index = np.full(len(pixels), -1, np.int64)
    new_index[nodes] = np.arange(len(nodes))
    parent = np.concatenate([np.concatenate([[bp], path[:-1]]) for path, bp in zip(paths, branch_parent)])
    parent = np.where(parent >= 0, new_index[np.maximum(parent, 0)], -1)
    level = np.zeros(len(paths), np.int64)  # branch level: parent branch's + 1 (paths come parents first)
    branch_of = np.repeat(np.arange(len(paths)), [len(p) for p in paths])
    for b in range(1, len(paths)):
        level[b] = level[branch_of[parent[new_index[paths[b][0]]]]] + 1
    positions = camera.unproject(pixels[nodes], metres(camera, depth[nodes]))
    radius = float(camera.metres_per_pixel(metres(camera, np.median(depth))))
    return Skeleton(positions, parent, np.full(len(nodes), radius), np.minimum(level[branch_of], 255))
