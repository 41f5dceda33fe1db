"""Phyllotaxis twig-and-leaf modules (thesis 003 section 3.2.5): small leafy twigs grown at the tips of any skeleton.

In: a Skeleton, a pattern name (opposite, alternate, whorled), an rng. Out: the Skeleton with twigs and leaf cards.
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from .rewrite import parse_modules
from ..skeleton import Skeleton
from .turtle import interpret, leaf_cards

__all__ = ["PATTERNS", "add_twigs", "twig_template"]

# Thesis 003 section 3.2.5: opposite (maple-like) and alternate (cherry-like); whorled is only named there, so
# the digest's default (3.8) puts four leaves around each node, repeated like the others.
PATTERNS: dict[str, str] = {
    "opposite": "F[+F][-F]F[+F][-F]F[+F][-F]F",
    "alternate": "F[+F]F[-F]F[+F]F[-F]F",
    "whorled": "F[+F][-F][&F][^F]F[+F][-F][&F][^F]F[+F][-F][&F][^F]F",
}


def twig_template(pattern: str, angle: float, step: float, rng: np.random.Generator):
    """The twig of `pattern` drawn in turtle-local axes (x = heading, y = left, z = up) from the origin.

    Returns the TurtlePath and the template's tips (one leaf card each, per the digest: one card per terminal F).
    """
    if pattern not in PATTERNS:
        raise ParameterError("pattern", pattern, f"one of {sorted(PATTERNS)}")
    modules = [(symbol, ()) for symbol, _ in parse_modules(PATTERNS[pattern], "pattern")]
    path = interpret(modules, angle=angle, step=step, width=1.0, width_ratio=1.0, rng=rng, start_frame=np.eye(3))
    return path, path.tips


def _tip_frames(skeleton: Skeleton, tips: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(T, 3, 3) frames [H L U] at the tips: H along the last segment, L rolled by `roll` radians about H."""
    heading = skeleton.positions[tips].astype(np.float64) - skeleton.positions[skeleton.parent[tips]]
    heading /= np.linalg.norm(heading, axis=1, keepdims=True)
    reference = np.where(np.abs(heading[:, 2:3]) > 0.9, [[1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    left = reference - heading * np.einsum("ti,ti->t", reference, heading)[:, None]
    left /= np.linalg.norm(left, axis=1, keepdims=True)
    left = np.cos(roll)[:, None] * left + np.sin(roll)[:, None] * np.cross(heading, left)
    return np.stack([heading, left, np.cross(heading, left)], axis=2)


def add_twigs(skeleton: Skeleton, pattern: str, rng: np.random.Generator, *, angle: float = 45.0,
              step: float = 0.04, leaf_size: float = 0.08, leaf_aspect: float = 0.5, scale_jitter: float = 0.15,
              taper: float = 0.85, tips: np.ndarray | None = None) -> Skeleton:
    """Grow one `pattern` twig (PATTERNS) with a leaf card on each terminal F at every chosen tip.

    angle : degrees, the twig's branching angle (digest default 45); step : metres per twig internode (0.04).
    leaf_size : metres, card length; leaf_aspect : card width / length.
    scale_jitter : each twig is scaled by U(1 - j, 1 + j) and rolled about its tip by U(0, 360) degrees.
    taper : radius factor per twig internode, starting from the tip's radius.
    tips : (T,) int node indices to grow from; default every tip whose parent edge has non-zero length.
    The twig's axis continues the tip's branch (same order); its side shoots are one order higher.
    Existing nodes and leaves keep their indices; the twig nodes are appended.
    """
    if tips is None:
        tips = skeleton.tips[skeleton.segment_lengths[skeleton.tips] > 0]
    tips = np.asarray(tips, np.int64)
    if len(tips) and (tips.min() < 1 or tips.max() >= len(skeleton)):
        raise ParameterError("tips", tips.tolist()[:5], f"node indices in [1, {len(skeleton) - 1}]")
    if not 0 <= scale_jitter < 1:
        raise ParameterError("scale_jitter", scale_jitter, "a fraction in [0, 1)")
    path, template_tips = twig_template(pattern, angle, step, rng)
    if len(tips) == 0:
        return skeleton
    roll = rng.uniform(0, 2 * np.pi, len(tips))
    scale = rng.uniform(1 - scale_jitter, 1 + scale_jitter, len(tips))
    frames = _tip_frames(skeleton, tips, roll) * scale[:, None, None]

    n_old, n_template = len(skeleton), len(path.positions) - 1  # template node 0 is the tip itself
    local = path.positions[1:]
    positions = skeleton.positions[tips][:, None, :] + np.einsum("tij,kj->tki", frames, local)
    base = n_old + n_template * np.arange(len(tips))
    template_parent = path.parent[1:].astype(np.int64)
    parent = np.where(template_parent[None, :] == 0, tips[:, None], base[:, None] + template_parent[None, :] - 1)
    depth = np.zeros(len(path.positions))
    for k in range(1, len(path.positions)):  # a template of a few dozen nodes, built once per call
        depth[k] = depth[path.parent[k]] + 1
    radius = skeleton.radius[tips][:, None] * taper ** depth[None, 1:]
    order = np.minimum(skeleton.order[tips][:, None].astype(np.int64) + path.order[None, 1:], 255)

    cards = leaf_cards(path.positions[template_tips], path.frames[template_tips], leaf_size,
                       leaf_size * leaf_aspect, 0.0, -np.pi / 2).astype(np.float64)  # card plane = twig plane
    world = np.zeros((len(tips), 4, 4))
    world[:, :3, :3], world[:, :3, 3], world[:, 3, 3] = frames, skeleton.positions[tips], 1.0
    leaves = np.einsum("tij,kjl->tkil", world, cards).reshape(-1, 4, 4)
    leaf_node = (base[:, None] + template_tips[None, :] - 1).ravel()

    return Skeleton(positions=np.concatenate([skeleton.positions, positions.reshape(-1, 3)]),
                    parent=np.concatenate([skeleton.parent, parent.ravel()]),
                    radius=np.concatenate([skeleton.radius, radius.ravel()]),
                    order=np.concatenate([skeleton.order, order.ravel()]),
                    leaves=np.concatenate([skeleton.leaves, leaves.astype(np.float32)]),
                    leaf_node=np.concatenate([skeleton.leaf_node, leaf_node]))
