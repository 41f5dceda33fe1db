"""Self-organizing tree growth (Palubicki et al. 2009 as thesis 000 uses it): space colonization or shadow
propagation, Borchert-Honda or priority allocation, in any growth space. Returns a `Skeleton` (metres, Z up).

`grow(params, rng)` builds the crown space from the dictionary and grows a bole into it; `grow_in_space(params,
rng, space=..., guide=..., markers=..., steering=...)` takes what a dictionary cannot hold (any GrowthSpace, a
guide skeleton, explicit markers, a MarkerSteering of direction field and brush strokes). `Colonizer` is the
growing tree, one `step()` at a time; `bole_guide` and `seed_from_guide` make the skeleton it starts from.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .allocation import allocate, jump_tables, path_products, subtree_sums
from .params import at_iteration, validate
from ..errors import ParameterError
from .growth_space import GrowthSpace, SuperquadricLobe, profile_crown, random_lobes, PROFILE_SHAPES
from ..geometry.radii import pipe_model_radii
from ..geometry.vectors import unit_vectors, unit_vectors_and_lengths
from .shadow import ShadowGrid
from ..skeleton import Skeleton
from .steering import MarkerSteering

__all__ = ["grow", "grow_in_space", "crown_space", "Colonizer", "bole_guide", "seed_from_guide", "REFERENCE_INTERNODE"]

REFERENCE_INTERNODE = 0.1  # metres per internode length at reference scale (digest convention)
_CANDIDATE_BUDS = 6        # nearest buds tested per marker for "nearest bud that perceives it"
_UP = np.array([0.0, 0.0, 1.0])
_LEAF_TILT = np.radians(55.0)  # leaves point out of their twig at this angle


def _frame(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to each direction (N, 3) and to each other."""
    reference = np.where(np.abs(directions[:, 2:3]) < 0.9, _UP, np.array([1.0, 0.0, 0.0]))
    u = unit_vectors(np.cross(directions, reference))
    return u, np.cross(directions, u)


def _turn(directions: np.ndarray, angle: float, azimuth: np.ndarray) -> np.ndarray:
    """Directions tilted by `angle` radians away from `directions`, toward azimuth (N,) radians."""
    u, w = _frame(directions)
    side = np.cos(azimuth)[:, None] * u + np.sin(azimuth)[:, None] * w
    return np.cos(angle) * directions + np.sin(angle) * side


class Colonizer:
    """A tree growing in a space: node and bud arrays, markers, one `step()` per growth iteration.

    Node arrays (first `n_nodes` rows valid): positions (N, 3) float64 metres, parent (N,) int64, order (N,),
    lateral (N,) bool (starts an axis), axis (N,) start node of its axis, birth (N,) step, guide (N,) bool,
    alive (N,) bool. Buds (B rows): host node, direction (B, 3) unit, order, apical, idle steps, phyllotaxis
    azimuth (radians). Markers: `markers` (M, 3) float64 metres with `marker_alive` (M,) bool.
    """

    def __init__(self, params: dict, rng: np.random.Generator, space: GrowthSpace, internode_length: float,
                 seed_nodes: dict, markers: np.ndarray | None = None, steering: MarkerSteering | None = None):
        self.params, self.rng, self.space, self.il = params, rng, space, float(internode_length)
        self.iteration, self._idle_steps, self.last_growth = 0, 0, 0
        n = len(seed_nodes["positions"])
        cap = max(1024, 2 * n)
        self.positions = np.zeros((cap, 3))
        self.parent = np.full(cap, -1, np.int64)
        self.order = np.zeros(cap, np.int64)
        self.lateral = np.zeros(cap, bool)
        self.axis = np.zeros(cap, np.int64)
        self.birth = np.zeros(cap, np.int64)
        self.guide = np.zeros(cap, bool)
        self.alive = np.zeros(cap, bool)
        self.low_light = np.zeros(cap, np.int64)
        self.n_nodes = 0
        ids = self._add_nodes(seed_nodes["positions"], seed_nodes["parent"], seed_nodes["order"],
                              seed_nodes["lateral"])
        self.guide[ids] = True
        self.buds = {k: np.asarray(v) for k, v in seed_nodes["buds"].items()}
        self.buds["idle"] = np.zeros(len(self.buds["host"]), np.int64)
        if markers is None:
            il3 = self.il ** 3
            markers = space.sample_markers(params["marker_density"] / il3, params["max_markers"], rng)
        self.markers = np.asarray(markers, np.float64)
        self.marker_alive = np.ones(len(self.markers), bool)
        self.steering = steering.at(self.markers) if steering is not None else None
        self._marker_tree = cKDTree(self.markers)
        self.shadow = None
        if params["resource"] == "shadow":
            self.shadow = ShadowGrid(space, self.il, params["shadow_a"], params["shadow_b"],
                                     params["shadow_depth"], params["shadow_exposure"], self.positions[:n])
            self.shadow.cast(self.positions[:n])
        self._remove_markers(self.positions[:n], params["occupancy_radius"] * self.il)

    # ------------------------------------------------------------------ storage
    def _add_nodes(self, positions, parent, order, lateral) -> np.ndarray:
        k = len(positions)
        if self.n_nodes + k > len(self.positions):
            cap = max(2 * len(self.positions), self.n_nodes + k)
            for name in ("positions", "parent", "order", "lateral", "axis", "birth", "guide", "alive", "low_light"):
                old = getattr(self, name)
                new = np.zeros((cap,) + old.shape[1:], old.dtype)
                new[: self.n_nodes] = old[: self.n_nodes]
                setattr(self, name, new)
        ids = np.arange(self.n_nodes, self.n_nodes + k)
        self.positions[ids], self.parent[ids], self.order[ids] = positions, parent, order
        self.lateral[ids] = lateral
        self.alive[ids], self.birth[ids] = True, self.iteration
        self.n_nodes += k
        # Parents come first, so a new node's axis is its own (lateral) or its parent's, already known,
        # except for chains added in one call (seed nodes), resolved by repeated gathers.
        axis = np.where(lateral, ids, np.asarray(parent))
        self.axis[ids] = axis
        while True:
            resolved = np.where(self.lateral[ids], ids, self.axis[self.parent[ids]])
            if np.array_equal(resolved, self.axis[ids]):
                return ids
            self.axis[ids] = resolved

    def _remove_markers(self, centres: np.ndarray, radius: float) -> None:
        if not len(centres):
            return
        taken = self._marker_tree.query_ball_point(centres, radius, return_sorted=False)
        self.marker_alive[np.concatenate(taken).astype(np.int64)] = False

    @property
    def markers_alive(self) -> np.ndarray:
        """(M', 3) float64 metres, the markers not yet taken by an occupancy zone."""
        return self.markers[self.marker_alive]

    @property
    def node_positions(self) -> np.ndarray:
        return self.positions[: self.n_nodes]

    # ------------------------------------------------------------------ perception
    def _perceive(self, p: dict, bud_positions: np.ndarray):
        """Q, optimal direction and steering per bud from the markers (digest 1.2, eq. 2.1)."""
        buds = len(bud_positions)
        light = np.zeros(buds)
        optimal = np.zeros((buds, 3))
        reach = p["perception_radius"] * self.il
        # Only markers in the buds' bounding box grown by the perception radius can be perceived; early
        # on, when the crown is a sapling, that skips most of the tree query.
        low, high = bud_positions.min(axis=0) - reach, bud_positions.max(axis=0) + reach
        near_box = self.marker_alive & np.all((self.markers >= low) & (self.markers <= high), axis=1)
        alive = np.flatnonzero(near_box)
        if not buds or not len(alive):
            return light, optimal, None
        k = min(_CANDIDATE_BUDS, buds)
        distance, nearest = cKDTree(bud_positions).query(self.markers[alive], k=k, distance_upper_bound=reach)
        distance, nearest = distance.reshape(len(alive), k), nearest.reshape(len(alive), k)
        seen = nearest[:, 0] < buds  # markers with any bud in reach: the only ones worth the cone test
        alive, distance, nearest = alive[seen], distance[seen], nearest[seen]
        valid = nearest < buds
        nearest = np.where(valid, nearest, 0)
        offset = self.markers[alive][:, None, :] - bud_positions[nearest]          # (M, k, 3)
        cosine = np.einsum("mkd,mkd->mk", offset, self.buds["direction"][nearest])
        cos_half = np.cos(np.radians(p["perception_angle"]) / 2)
        perceived = valid & (cosine >= cos_half * np.where(valid, distance, 1.0))
        owned = perceived.any(axis=1)
        pick = np.argmax(perceived, axis=1)[owned]
        rows = np.flatnonzero(owned)
        owner = nearest[rows, pick]
        unit = offset[rows, pick] / np.maximum(distance[rows, pick], 1e-12)[:, None]
        count = np.bincount(owner, minlength=buds)
        for d in range(3):
            optimal[:, d] = np.bincount(owner, weights=unit[:, d], minlength=buds)
        optimal = unit_vectors(optimal)
        light = (count > 0).astype(np.float64) if p["light_model"] == "binary" else count / (count + 3.0)
        steer = None
        if self.steering is not None:
            steer = self.steering.per_bud(alive[rows], owner, buds, p["attraction_weight"])
        return light, optimal, steer

    # ------------------------------------------------------------------ one growth step
    def step(self) -> int:
        """One iteration: perceive, allocate, grow, remove taken markers, shed. Returns internodes added."""
        p = at_iteration(self.params, self.iteration)
        buds = self.buds
        host = buds["host"]
        bud_positions = self.positions[host]
        if self.shadow is None:
            light, optimal, steer = self._perceive(p, bud_positions)
        else:
            light = self.shadow.light(bud_positions)
            optimal = self.shadow.best_directions(bud_positions, buds["direction"],
                                                  np.cos(np.radians(p["perception_angle"]) / 2),
                                                  p["shadow_direction"])
            steer = None
        n = self.n_nodes
        tables = jump_tables(self.parent[:n])
        resource, subtree_light = allocate(
            self.parent[:n], self.lateral[:n], self.axis[:n], host, buds["apical"], light,
            model=p["allocation"], alpha=p["alpha"], lam=p["lambda"], kappa=p["kappa"], tables=tables)
        whole = np.floor(resource)
        count = np.where(resource >= 1.0, np.minimum(whole, p["max_internodes_per_step"]), 0).astype(np.int64)
        length = np.divide(resource, whole, out=np.zeros_like(resource), where=whole >= 1) * self.il
        if steer is not None:
            optimal = optimal + steer
        if p["shed_ratio"] > 0:
            self._shed(p, tables, subtree_light, n)
            count[~self.alive[host]] = 0
        added, grew = self._extend(p, count, length, optimal)
        self._bud_fates(p, grew)
        if added:
            self.last_growth = self.iteration
        self.iteration += 1
        self._idle_steps = 0 if added else self._idle_steps + 1
        return added

    def _extend(self, p: dict, count: np.ndarray, length: np.ndarray, optimal: np.ndarray):
        """Grow each bud `count` internodes of `length` metres along eq. 2.3; new nodes stay inside the space."""
        buds = self.buds
        growing = np.flatnonzero(count > 0)
        grew = np.zeros(len(count), np.int64)
        if not len(growing):
            return 0, grew
        current = buds["host"][growing].copy()
        heading = buds["direction"][growing].copy()
        pull = p["optimal_weight"] * optimal[growing] + p["tropism"] * _UP
        remaining = count[growing].copy()
        new_nodes, new_dirs, new_orders = [], [], []
        for sub in range(int(remaining.max())):  # at most max_internodes_per_step passes, each over all buds
            active = np.flatnonzero(remaining > sub)
            if not len(active):
                break
            direction, norm = unit_vectors_and_lengths(p["default_weight"] * heading[active] + pull[active])
            direction = np.where(norm[:, None] > 1e-9, direction, heading[active])
            candidate = self.positions[current[active]] + direction * length[growing[active], None]
            inside = self.space.contains(candidate)
            remaining[active[~inside]] = 0  # the envelope stops this bud for this step
            active, direction, candidate = active[inside], direction[inside], candidate[inside]
            if not len(active):
                break
            bud = growing[active]
            starts_axis = (grew[bud] == 0) & ~buds["apical"][bud]
            ids = self._add_nodes(candidate, current[active], buds["order"][bud], starts_axis)
            grew[bud] += 1
            azimuth = buds["phyllo"][bud]
            new_dirs.append(_turn(direction, np.radians(p["branch_angle"]), azimuth))
            buds["phyllo"][bud] = azimuth + np.radians(p["phyllotaxis"])
            new_nodes.append(ids)
            new_orders.append(buds["order"][bud] + 1)
            current[active], heading[active] = ids, direction
        buds["host"][growing], buds["direction"][growing] = current, heading
        buds["apical"][grew > 0] = True  # a lateral bud that grew now leads its own axis
        if new_nodes:
            ids = np.concatenate(new_nodes)
            self._add_buds(ids, np.concatenate(new_dirs), np.concatenate(new_orders))
            self._remove_markers(self.positions[ids], p["occupancy_radius"] * self.il)
            if self.shadow is not None:
                self.shadow.cast(self.positions[ids])
            return len(ids), grew
        return 0, grew

    def _add_buds(self, hosts: np.ndarray, directions: np.ndarray, orders: np.ndarray) -> None:
        k = len(hosts)
        fresh = {"host": hosts, "direction": directions, "order": orders, "apical": np.zeros(k, bool),
                 "idle": np.zeros(k, np.int64), "phyllo": self.rng.uniform(0, 2 * np.pi, k)}
        self.buds = {name: np.concatenate([self.buds[name], fresh[name]]) for name in self.buds}

    def _bud_fates(self, p: dict, grew: np.ndarray) -> None:
        """Dormant buds age and die after bud_lifetime steps; sympodial apices abort after growing."""
        buds, old = self.buds, len(grew)  # buds past `old` were made this step and stay fresh
        buds["idle"][:old] = np.where(grew > 0, 0, buds["idle"][:old] + 1)
        keep = buds["idle"] < p["bud_lifetime"]
        if p["apical_abort"] > 0:
            aborted = (grew > 0) & buds["apical"][:old]
            aborted &= self.rng.random(old) < p["apical_abort"]
            keep[:old] &= ~aborted
        keep &= self.alive[buds["host"]]
        self.buds = {name: value[keep] for name, value in buds.items()}

    def _shed(self, p: dict, tables, subtree_light: np.ndarray, n: int) -> None:
        """Palubicki's shedding: a branch whose light per internode stays below shed_ratio times the whole
        tree's falls off. Relative to the tree, so a crown that has used up its space does not shed itself."""
        size = subtree_sums(tables, self.alive[:n].astype(np.float64))
        ratio = subtree_light / np.maximum(size, 1.0)
        branch = self.lateral[:n] & ~self.guide[:n] & self.alive[:n]
        branch[0] = False
        low = branch & (ratio < p["shed_ratio"] * ratio[0])
        self.low_light[:n] = np.where(low, self.low_light[:n] + 1, 0)
        falling = self.low_light[:n] >= p["shed_patience"]
        if not falling.any():
            return
        dead = path_products(tables, (~falling).astype(np.float64)) == 0
        dying = dead & self.alive[:n]
        if self.shadow is not None:
            self.shadow.cast(self.positions[:n][dying], sign=-1.0)
        self.alive[:n] &= ~dead

    def run(self, progress=None) -> "Colonizer":
        """Step until `iterations`, until no bud is left, or after 2 steps in a row without growth."""
        for _ in range(self.params["iterations"] - self.iteration):
            if not len(self.buds["host"]) or self._idle_steps >= 2:
                break
            added = self.step()
            if progress is not None:
                progress.update(1)
                progress.set_postfix(nodes=self.n_nodes, added=added)
        return self

    # ------------------------------------------------------------------ output
    def to_skeleton(self) -> Skeleton:
        """The grown tree (shed branches dropped) with pipe-model radii and leaves on the youngest internodes."""
        p = self.params
        keep = np.flatnonzero(self.alive[: self.n_nodes])
        new_index = np.full(self.n_nodes, -1, np.int64)
        new_index[keep] = np.arange(len(keep))
        parent = np.where(self.parent[keep] >= 0, new_index[np.maximum(self.parent[keep], 0)], -1)
        positions = self.positions[keep]
        radius = pipe_model_radii(parent, p["tip_diameter"] * self.il / 2, p["pipe_exponent"])
        order = np.minimum(self.order[keep], 255)
        leaves, leaf_node = self._leaves(positions, parent, order, self._leaf_nodes(keep))
        return Skeleton(positions, parent, radius, order, leaves, leaf_node)

    def _leaf_nodes(self, keep: np.ndarray) -> np.ndarray:
        """(K,) bool over kept nodes: the internodes each axis grew in its last leaf_age growing steps."""
        p, n = self.params, self.n_nodes
        birth, axis = self.birth[:n], self.axis[:n]
        youngest = np.full(n, -1, np.int64)
        np.maximum.at(youngest, axis[self.alive[:n]], birth[self.alive[:n]])
        young = (birth > youngest[axis] - p["leaf_age"]) & (self.order[:n] >= p["leaf_min_order"])
        young &= ~self.guide[:n]
        return young[keep]

    def _leaves(self, positions, parent, order, young):
        p = self.params
        nodes = np.repeat(np.flatnonzero(young), p["leaves_per_node"]) if p["leaf_age"] else np.zeros(0, int)
        if not len(nodes):
            return np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int32)
        twig = unit_vectors(positions[nodes] - positions[parent[nodes]])
        azimuth = self.rng.uniform(0, 2 * np.pi, len(nodes))
        along = _turn(twig, _LEAF_TILT, azimuth)
        side, norm = unit_vectors_and_lengths(np.cross(along, _UP))
        side = np.where(norm[:, None] > 1e-6, side, _frame(along)[0])
        facing = np.cross(along, side)
        width = p["leaf_size"] * self.il
        transforms = np.zeros((len(nodes), 4, 4))
        transforms[:, :3, 0] = side * width
        transforms[:, :3, 1] = facing * width
        transforms[:, :3, 2] = along * width * p["leaf_aspect"]
        transforms[:, :3, 3] = positions[nodes]
        transforms[:, 3, 3] = 1.0
        return transforms.astype(np.float32), nodes.astype(np.int32)


# ---------------------------------------------------------------------- seeds: guides and boles
def seed_from_guide(guide: Skeleton, buds_on: str, rng: np.random.Generator, p: dict) -> dict:
    """Seed arrays from a guide skeleton: its nodes kept as given, apical buds on its tips, laterals optional."""
    positions = guide.positions.astype(np.float64)
    parent = guide.parent.astype(np.int64)
    continuation = guide.continuation
    lateral = np.ones(len(guide), bool)
    lateral[continuation[continuation >= 0]] = False
    tips = guide.tips if len(guide) > 1 else np.zeros(1, np.int64)
    tip_dir = np.tile(_UP, (len(tips), 1))
    if len(guide) > 1:
        segment, norm = unit_vectors_and_lengths(positions[tips] - positions[parent[tips]])
        tip_dir = np.where(norm[:, None] > 1e-12, segment, _UP)
    hosts, dirs, apical = [tips], [tip_dir], [np.ones(len(tips), bool)]
    if buds_on == "all" and len(guide) > 1:
        inner = np.arange(1, len(guide))
        axis_dir = unit_vectors(positions[inner] - positions[parent[inner]])
        azimuth = rng.uniform(0, 2 * np.pi) + np.arange(len(inner)) * np.radians(p["phyllotaxis"])
        hosts.append(inner)
        dirs.append(_turn(axis_dir, np.radians(p["branch_angle"]), azimuth))
        apical.append(np.zeros(len(inner), bool))
    elif buds_on != "tips" and buds_on != "all":
        raise ParameterError("guide_buds", buds_on, "'tips' or 'all'")
    host = np.concatenate(hosts)
    order = guide.order.astype(np.int64)
    is_apical = np.concatenate(apical)
    buds = {"host": host, "direction": np.concatenate(dirs), "apical": is_apical,
            "order": np.where(is_apical, order[host], order[host] + 1),
            "phyllo": rng.uniform(0, 2 * np.pi, len(host))}
    return {"positions": positions, "parent": parent, "order": order, "lateral": lateral, "buds": buds}


def bole_guide(p: dict, rng: np.random.Generator, il: float) -> Skeleton:
    """The stems from the ground to 1 IL inside the crown base, straight, as a guide (no lateral buds)."""
    top = (p["crown_base"] + 1.0) * il
    segments = max(1, int(np.ceil(top / il)))
    tilt = np.zeros(p["stems"])
    tilt[1:] = np.radians(p["stem_spread"])
    if p["stems"] > 1:
        tilt[0] = np.radians(p["stem_spread"]) * 0.3
    azimuth = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(p["stems"]) / p["stems"]
    direction = np.stack([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)], axis=1)
    steps = np.arange(1, segments + 1) / segments * top / np.cos(tilt)[:, None]  # (stems, segments)
    points = (steps[..., None] * direction[:, None, :]).reshape(-1, 3)
    index = np.arange(1, len(points) + 1).reshape(p["stems"], segments)
    parent = np.concatenate([np.zeros((p["stems"], 1), np.int64), index[:, :-1]], axis=1).reshape(-1)
    positions = np.concatenate([np.zeros((1, 3)), points])
    return Skeleton(positions, np.concatenate([[-1], parent]), np.full(len(positions), il * 0.1),
                    np.zeros(len(positions), np.uint8))


def crown_space(params: dict, rng: np.random.Generator, internode_length: float = REFERENCE_INTERNODE) -> GrowthSpace:
    """The growth space a parameter dictionary describes (crown_* keys, IL), in metres."""
    p = validate(params)
    radius, height, base = (p[k] * internode_length for k in ("crown_radius", "crown_height", "crown_base"))
    shape = p["crown_shape"]
    if shape in PROFILE_SHAPES:
        return profile_crown(shape, radius, height, base)
    if shape == "superquadric":
        return SuperquadricLobe((0.0, 0.0, base + height / 2), (radius, radius, height / 2), p["crown_exponent"])
    exponent = p["crown_exponent"]
    return random_lobes(rng, p["crown_lobes"], radius, height, base, (0.85 * exponent, 1.15 * exponent))


def grow_in_space(params: dict, rng: np.random.Generator, *, space: GrowthSpace,
                  internode_length: float = REFERENCE_INTERNODE, guide: Skeleton | None = None,
                  guide_buds: str = "all", markers: np.ndarray | None = None,
                  steering: MarkerSteering | None = None) -> Skeleton:
    """Grow in a given space (metres). The guide's nodes come first in the result, exactly as given.

    guide      : main branches already known; growth continues from its tips (and, with guide_buds
                 "all", from lateral buds on its nodes). Without one, a bole from params grows to the crown.
    markers    : (M, 3) float64 metres, explicit markers instead of sampling the space.
    steering   : a MarkerSteering (direction field eq. 3.6 and/or brush strokes eq. 4.2-4.3).
    """
    p = validate(params)
    if not isinstance(space, GrowthSpace):
        raise ParameterError("space", type(space).__name__, "a species.colonization.GrowthSpace")
    if not internode_length > 0:
        raise ParameterError("internode_length", internode_length, "a length > 0 metres")
    if guide is None:
        seed = seed_from_guide(bole_guide(p, rng, internode_length), "tips", rng, p)
    else:
        seed = seed_from_guide(guide, guide_buds, rng, p)
    colonizer = Colonizer(p, rng, space, internode_length, seed, markers=markers, steering=steering)
    return colonizer.run().to_skeleton()


def grow(params: dict, rng: np.random.Generator) -> Skeleton:
    """Grow the tree a colonization dictionary describes, scaled so its height is params["height"] metres."""
    p = validate(params)
    skeleton = grow_in_space(p, rng, space=crown_space(p, rng))
    if p["height"] <= 0:
        return skeleton
    scale = p["height"] / max(skeleton.height, 1e-9)
    leaves = skeleton.leaves.copy()
    leaves[:, :3, :] *= scale
    return Skeleton(skeleton.positions * scale, skeleton.parent, skeleton.radius * scale, skeleton.order,
                    leaves, skeleton.leaf_node)
