"""Growth of a hand-modelled tree (seed 000 ch. 4-5): self-organizing growth inside the drawn lobes, from the drawn
main branches, toward the painted markers, with a colonization preset's growth parameters.

In: lobe meshes (closed trimesh.Trimesh, metres, Z up), main branches (polyline (K, 3) metres, parent branch index;
-1 for the trunk), painted markers (M, 3) metres, a preset name and overrides, a Generator. Out: a `Skeleton`
whose first nodes are the drawn branches, resampled every internode length.
"""
from __future__ import annotations

import numpy as np
import trimesh

from species.colonization import (grow_in_space, MarkerSteering, MeshSpace, PointSpace, REFERENCE_INTERNODE,
                                  SCHEMA, UnionSpace, validate)
from species.errors import ParameterError, TreefarmError
from species.presets import get_preset, list_presets, PresetError
from species.skeleton import Skeleton

from .strokes import arc_lengths, resample_polyline

__all__ = ["ModelError", "grow_model", "colonization_presets", "model_params", "branch_guide", "model_space",
           "perceived_markers", "perception_at_budget", "MODEL_DEFAULTS", "REACH", "MIN_PERCEIVED"]

# What modelling changes in a preset before the user's overrides: a marker budget that keeps growth live.
MODEL_DEFAULTS = {"max_markers": 4000, "leaf_age": 3}
REACH = 1.5  # IL: buds may grow this far round painted markers and drawn branches, outside the lobes
# Markers a bud's perception cone must hold on average for growth to spread on through the lobes (fewer, and
# most buds perceive none and die); a marker budget under the preset's density widens the cone to this.
MIN_PERCEIVED = 8


class ModelError(TreefarmError):
    """A model that cannot grow: an unknown preset, malformed branches, nothing to grow into."""


def colonization_presets() -> list[str]:
    """The names of the species presets that grow by space colonization (the page's menu), sorted."""
    return [preset.name for preset in list_presets("colonization")]


def model_params(preset: str, params: dict | None = None) -> dict:
    """The validated growth dictionary: the preset's typical member, MODEL_DEFAULTS, then `params` on top."""
    try:
        template = get_preset(preset)
    except PresetError:
        raise ModelError(f"preset {preset!r} is unknown; allowed: {', '.join(colonization_presets())}") from None
    if template.generator != "colonization":
        raise ModelError(f"preset {preset!r} grows by {template.generator}; allowed: a colonization preset "
                         f"({', '.join(colonization_presets())})")
    if params is not None and not isinstance(params, dict):
        raise ParameterError("params", type(params).__name__, "a dict of colonization parameters")
    return validate({**template.base_params(), **MODEL_DEFAULTS, **(params or {})})


def _polyline(points, what: str) -> np.ndarray:
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2 or not np.all(np.isfinite(points)):
        raise ModelError(f"{what} must be finite points of shape (K >= 2, 3); got shape {points.shape}")
    return points


def _distance_to(points: np.ndarray, point: np.ndarray) -> float:
    return float(np.linalg.norm(points - point, axis=1).min())


def branch_guide(branches, internode_length: float) -> Skeleton:
    """The drawn main branches as one guide skeleton: each polyline resampled every internode length; a branch
    starts at the node of its parent branch nearest its first point (its own first point dropped when it lies
    within half an internode of there). Exactly one branch is the trunk (parent -1); order = nesting depth.
    Strokes may be drawn either way: the trunk is turned to start at its lower end, a branch at its end nearer
    its parent branch."""
    lines, parents = [], []
    for index, entry in enumerate(branches):
        if not isinstance(entry, (tuple, list)) or len(entry) != 2:
            raise ModelError(f"branch {index} must be (polyline, parent index); got {type(entry).__name__}")
        lines.append(_polyline(entry[0], f"branch {index}"))
        parent = entry[1]
        if isinstance(parent, bool) or not isinstance(parent, (int, np.integer)) or not -1 <= parent < len(branches) \
                or parent == index:
            raise ModelError(f"branch {index} has parent {parent!r}; allowed: -1 (the trunk) or another branch's "
                             f"index in 0..{len(branches) - 1}")
        parents.append(int(parent))
    trunks = [i for i, p in enumerate(parents) if p == -1]
    if len(trunks) != 1:
        raise ModelError(f"the branches have {len(trunks)} trunks (parent -1); allowed: exactly one")
    positions, parent_ids, orders = [], [], []
    nodes_of: dict[int, np.ndarray] = {}
    order_of = {trunks[0]: 0}
    pending, count = list(trunks), 0
    while pending:  # a handful of drawn branches, parents before children
        index = pending.pop(0)
        line = lines[index]
        if parents[index] < 0 and line[-1, 2] < line[0, 2]:
            line = line[::-1]
        elif parents[index] >= 0:
            host_points = np.concatenate(positions)[nodes_of[parents[index]]]
            if _distance_to(host_points, line[-1]) < _distance_to(host_points, line[0]):
                line = line[::-1]
        k = max(2, int(np.ceil(arc_lengths(line)[-1] / internode_length)) + 1)
        points = resample_polyline(line, k)
        ids = count + np.arange(k)
        parent = np.concatenate([[-1], ids[:-1]])
        if parents[index] >= 0:
            host = nodes_of[parents[index]]
            attach = host[np.argmin(np.linalg.norm(np.concatenate(positions)[host] - points[0], axis=1))]
            if np.linalg.norm(np.concatenate(positions)[attach] - points[0]) < internode_length / 2:
                points, ids, parent = points[1:], ids[:-1], parent[:-1]
            parent[0] = attach
        positions.append(points)
        parent_ids.append(parent)
        orders.append(np.full(len(points), order_of[index]))
        nodes_of[index] = ids
        count += len(points)
        for child in (i for i, p in enumerate(parents) if p == index):
            order_of[child] = order_of[index] + 1
            pending.append(child)
    if len(nodes_of) != len(lines):
        lost = sorted(set(range(len(lines))) - set(nodes_of))
        raise ModelError(f"branches {lost} do not descend from the trunk (their parents form a loop); allowed: "
                         "each branch's parents lead back to the trunk")
    positions = np.concatenate(positions)
    return Skeleton(positions, np.concatenate(parent_ids), np.full(len(positions), internode_length * 0.1),
                    np.minimum(np.concatenate(orders), 255))


def _default_trunk(lobes: list, internode_length: float) -> list:
    """A straight trunk from the origin to one internode inside the lowest lobe, under its centre."""
    lowest = min(lobes, key=lambda mesh: float(mesh.bounds[0, 2]))
    centre = np.asarray(lowest.vertices).mean(axis=0)
    top = np.array([centre[0], centre[1], float(lowest.bounds[0, 2]) + internode_length])
    return [(np.stack([np.zeros(3), top]), -1)]


def model_space(lobes: list, guide: Skeleton, markers: np.ndarray, internode_length: float):
    """The growth space: the lobes, and REACH internode lengths round the painted markers and the guide."""
    parts = [MeshSpace(vertices=mesh.vertices, faces=mesh.faces) for mesh in lobes]
    reach = REACH * internode_length
    parts.append(PointSpace(np.concatenate([guide.positions.astype(np.float64), markers]), reach))
    return UnionSpace(tuple(parts))


def perceived_markers(params: dict, markers_per_cubic_metre: float, internode_length: float) -> float:
    """The markers a bud's perception cone (radius, angle of `params`) holds on average at that density."""
    radius = params["perception_radius"] * internode_length
    cap = (1.0 - np.cos(np.radians(params["perception_angle"]) / 2)) / 2  # the cone's share of the ball
    return markers_per_cubic_metre * 4.0 / 3.0 * np.pi * radius ** 3 * cap


def perception_at_budget(params: dict, markers_per_cubic_metre: float, internode_length: float) -> dict:
    """`params` with the perception radius (and each schedule phase's) widened for markers sparser than the
    preset's density (a marker budget too small for the lobes): until a bud's cone holds MIN_PERCEIVED markers
    again, never further than the preset's own spacing would give, at most the schema's limit. Without it a bud
    perceives next to nothing and growth dies out round the drawn branches. The occupancy radius stays in
    internode lengths: it sets how closely branches pack, not how far buds look. `params` itself when the
    markers are as dense as the preset's."""
    spread = params["marker_density"] / internode_length ** 3 / markers_per_cubic_metre
    if not spread > 1.0:
        return params
    limit = SCHEMA["perception_radius"].high

    def radius(phase: dict) -> float:
        current = {**params, **phase}
        seen = perceived_markers(current, markers_per_cubic_metre, internode_length)
        widen = max(1.0, min(np.cbrt(MIN_PERCEIVED / seen), np.cbrt(spread)))
        return float(min(current["perception_radius"] * widen, limit))

    perceives = ("perception_radius", "perception_angle")
    schedule = [[start, {**phase, "perception_radius": radius(phase)} if any(k in phase for k in perceives)
                 else phase] for start, phase in params["schedule"]]
    return {**params, "perception_radius": radius({}), "schedule": schedule}


def grow_model(lobes: list[trimesh.Trimesh], branches: list[tuple[np.ndarray, int]], markers: np.ndarray,
               preset: str, params: dict | None, rng: np.random.Generator, *, brush_paths=(),
               brush_sigma: float | None = None, internode_length: float = REFERENCE_INTERNODE) -> Skeleton:
    """The tree grown inside `lobes` from `branches`, also into the painted `markers` (see the module).

    Markers fill the lobes at the preset's density, at most the marker budget (MODEL_DEFAULTS's unless `params`
    says otherwise; under the density, buds look further: `perception_at_budget`); the painted ones are added
    as they are and are reachable outside the lobes. Without branches, a trunk runs from the origin into the
    lowest lobe. brush_paths : the brush's paths (K, 3) metres; buds that perceive markers near
    them turn along them (eq. 4.2-4.3, sigma = brush_sigma, by default half of REACH internode lengths).
    Raises ModelError (a ValueError) for an unknown preset, bad branches, or nothing to grow into.
    """
    if not (np.isfinite(internode_length) and internode_length > 0):
        raise ModelError(f"internode length is {internode_length!r}; allowed: a finite length > 0 metres")
    p = model_params(preset, params)
    markers = np.zeros((0, 3)) if markers is None else np.asarray(markers, np.float64)
    if markers.size == 0:
        markers = np.zeros((0, 3))
    if markers.ndim != 2 or markers.shape[1] != 3 or not np.all(np.isfinite(markers)):
        raise ModelError(f"the painted markers must be finite points of shape (M, 3) metres; got shape "
                         f"{markers.shape}")
    lobes = list(lobes)
    for index, mesh in enumerate(lobes):
        if not isinstance(mesh, trimesh.Trimesh):
            raise ModelError(f"lobe {index} is a {type(mesh).__name__}; allowed: a closed trimesh.Trimesh")
    if not lobes and not len(markers):
        raise ModelError("the model is empty: allowed: at least one lobe or some painted markers to grow into")
    if not branches:
        branches = _default_trunk(lobes, internode_length) if lobes else [(np.stack([np.zeros(3),
                                                                                     markers.mean(axis=0)]), -1)]
    guide = branch_guide(branches, internode_length)
    space = model_space(lobes, guide, markers, internode_length)
    sampled = [markers]
    if lobes:
        lobe_space = UnionSpace(tuple(space.parts[:-1]))
        density = p["marker_density"] / internode_length ** 3
        sampled.insert(0, lobe_space.sample_markers(density, p["max_markers"], rng))
        if len(sampled[0]) >= p["max_markers"]:  # the budget, not the density, set the count
            lobe_volume = sum(abs(float(mesh.volume)) for mesh in lobes)  # overlaps count twice: a little wider
            p = perception_at_budget(p, len(sampled[0]) / lobe_volume, internode_length)
    steering = None
    if len(brush_paths):
        sigma = REACH * internode_length / 2 if brush_sigma is None else float(brush_sigma)
        steering = MarkerSteering(strokes=tuple(_polyline(path, "brush path") for path in brush_paths),
                                  sigma=sigma)
    return grow_in_space(p, rng, space=space, internode_length=internode_length, guide=guide, guide_buds="all",
                         markers=np.concatenate(sampled), steering=steering)
