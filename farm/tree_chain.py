"""One tree from species name and seed to table rows: sample -> grow -> mesh -> render -> encode.

`SpeciesChain` is the default tree builder (the real species and renderers functions, one ViewRenderer per
process); `tree_row` / `view_rows` turn its result into rows of the trees and views tables.
"""
from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

import renderers
import species
from species.timing import StageTimer

from .dataset import trees_schema
from .dataset.image_codec import encode_map

__all__ = ["BuiltTree", "SpeciesChain", "TreeBuilder", "tree_seed", "tree_id", "stage_rngs",
           "tree_row", "view_rows", "failed_tree_row", "to_json"]


def tree_seed(job_seed: int, index: int) -> int:
    """Tree `index`'s seed: 63 bits of `SeedSequence(job_seed).spawn(n)[index]` (the same for any n >= index+1)."""
    child = np.random.SeedSequence(job_seed, spawn_key=(index,))
    return int(child.generate_state(1, np.uint64)[0] >> np.uint64(1))


def stage_rngs(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """The sampler's and the renderer's generators of a tree seed (growth uses `species.rng_for(params)`)."""
    sample_seq, render_seq = np.random.SeedSequence(seed).spawn(2)
    return np.random.default_rng(sample_seq), np.random.default_rng(render_seq)


def tree_id(job_name: str, index: int) -> str:
    return f"{job_name}-{index:08d}"


def to_json(value: Any) -> str:
    """Canonical JSON (sorted keys, numpy values as plain numbers and lists): the same dict, the same text."""
    def plain(item):
        if isinstance(item, np.ndarray):
            return item.tolist()
        if isinstance(item, np.generic):
            return item.item()
        raise TypeError(f"{type(item).__name__} is not JSON-able")

    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=plain)


@dataclass
class BuiltTree:
    """What a tree builder returns: the parameter dictionary, skeleton, mesh and rendered views.

    views : list of `renderers.RenderedView` (index, name, camera with to_dict(), images by output name).
    """

    params: dict
    skeleton: Any
    mesh: Any
    views: list = field(default_factory=list)


class TreeBuilder(Protocol):
    def __call__(self, species_name: str, seed: int, timer: StageTimer) -> BuiltTree: ...


class SpeciesChain:
    """The real chain: species.sample -> species.grow -> species.build_mesh -> ViewRenderer.render.

    Made once per worker process (it holds the offscreen renderer); `spec` is the JobSpec.
    """

    def __init__(self, spec) -> None:
        self.spec = spec
        self._renderer = None

    def renderer(self):
        if self._renderer is None:
            self._renderer = renderers.ViewRenderer(size=self.spec.render.size)
        return self._renderer

    def __call__(self, species_name: str, seed: int, timer: StageTimer) -> BuiltTree:
        sample_rng, render_rng = stage_rngs(seed)
        with timer.stage("sample"):
            params = species.sample(species_name, sample_rng)
        built = BuiltTree(params=params, skeleton=None, mesh=None)
        with timer.stage("grow"):  # growth and meshing; a tree over the job's max_nodes fails before meshing
            built.skeleton, built.mesh = species.rebuild(params, max_nodes=self.spec.max_nodes)
        if self.spec.render.outputs:
            with timer.stage("render"):
                built.views = self.renderer().render(built.mesh, built.skeleton, self.spec.render.rig,
                                                     self.spec.render.outputs, rng=render_rng)
        return built


BuilderFactory = Callable[[Any], TreeBuilder]


# ---------------------------------------------------------------------- rows
def _list(array, dtype) -> np.ndarray:
    # A flat numpy array, not a Python list: pyarrow converts it to a list cell without a per-element loop.
    return np.ascontiguousarray(array, dtype).ravel()


def tree_row(spec, index: int, shard: int, species_name: str, seed: int, built: BuiltTree) -> dict:
    """A trees-table row of a successfully built tree (GLB exported here if the spec stores it)."""
    skeleton, mesh = built.skeleton, built.mesh
    row = _base_row(spec, index, shard, species_name, seed, built.params)
    row.update({
        "n_nodes": int(skeleton.n_nodes), "positions": _list(skeleton.positions, np.float32),
        "parent": _list(skeleton.parent, np.int32), "radius": _list(skeleton.radius, np.float32),
        "order": _list(skeleton.order, np.uint8), "leaves": _list(skeleton.leaves, np.float32),
        "leaf_node": _list(skeleton.leaf_node, np.int32),
        "glb": mesh.to_glb() if (spec.tables.store_glb and mesh is not None) else None,
        "height": float(skeleton.height), "crown_radius": float(skeleton.crown_radius),
        "n_branches": int(len(skeleton.branch_starts)), "n_leaves": int(skeleton.n_leaves),
        "bark_triangles": int(mesh.bark.n_faces) if mesh is not None else None,
        "leaf_triangles": int(mesh.leaves.n_faces) if mesh is not None else None,
        "n_vertices": int(mesh.n_vertices) if mesh is not None else None,
        "n_views": len(built.views),
    })
    return row


@functools.cache
def _tree_columns() -> tuple[str, ...]:
    return tuple(trees_schema().names)


def _base_row(spec, index, shard, species_name, seed, params) -> dict:
    row = dict.fromkeys(_tree_columns())
    row.update({"tree_id": tree_id(spec.name, index), "index": index, "shard": shard, "species": species_name,
                "seed": seed, "n_views": 0})
    if params is not None:
        row["generator"] = params.get("generator", "weber_penn")
        row["params_json"] = to_json(params)
    return row


def failed_tree_row(spec, index: int, shard: int, species_name: str, seed: int, params: dict | None,
                    error: str) -> dict:
    """A trees-table row of a tree whose build raised: ids, seed, params if sampled, and the error."""
    row = _base_row(spec, index, shard, species_name, seed, params)
    row["error"] = error
    return row


def view_rows(spec, index: int, shard: int, views: list) -> list[dict]:
    """Views-table rows of one tree: camera JSON and each output as PNG (16-bit with scale/offset for the outputs
    `renderers.OUTPUTS` declares float32, metric or not as it declares)."""
    rows = []
    for view in sorted(views, key=lambda v: v.index):
        row = {"tree_id": tree_id(spec.name, index), "index": index, "shard": shard, "view": int(view.index),
               "view_name": str(view.name), "camera_json": to_json(view.camera.to_dict())}
        for name in spec.tables.view_outputs:
            image, output = np.asarray(view.images[name]), renderers.OUTPUTS[name]
            if output.is_float == (image.dtype == np.uint8):
                raise TypeError(f"output {name!r} came back as {image.dtype}; the views schema stores it as "
                                f"{'a float' if output.is_float else 'a uint8'} map")
            png, scale, offset = encode_map(name, image, metric=output.metric)
            row[name] = png
            if output.is_float:
                row[f"{name}_scale"], row[f"{name}_offset"] = scale, offset
        rows.append(row)
    return rows
