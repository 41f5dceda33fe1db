"""A library GLB as a trimesh.Scene with its instanced leaves expanded, for tools that ignore
EXT_mesh_gpu_instancing (trimesh draws such a node's mesh once, at the node).

In: GLB bytes or a path. Out: a trimesh.Scene of the GLB's default scene (LOD0; Y up, metres, as in the file) with
one node per instance under each instancing node, so its triangle count is what a renderer draws.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from species.meshing.gltf import read_accessor, read_glb_chunks

__all__ = ["load_glb_scene", "instance_matrices", "INSTANCING"]

INSTANCING = "EXT_mesh_gpu_instancing"


def instance_matrices(document: dict, binary: bytes, attributes: dict) -> np.ndarray:
    """(K, 4, 4) float64 node-local matrices T R S of the instances an EXT_mesh_gpu_instancing `attributes`
    ({"TRANSLATION", "ROTATION", "SCALE": accessor index}, each optional) describes in a GLB's (document, binary
    chunk); ROTATION is x, y, z, w, float or normalized integers."""
    from scipy.spatial.transform import Rotation

    arrays = {name: _floats(document, binary, index) for name, index in attributes.items()
              if name in ("TRANSLATION", "ROTATION", "SCALE")}
    count = len(next(iter(arrays.values()))) if arrays else 0
    translation = arrays.get("TRANSLATION", np.zeros((count, 3)))
    rotation = Rotation.from_quat(arrays["ROTATION"]).as_matrix() if "ROTATION" in arrays else \
        np.broadcast_to(np.eye(3), (count, 3, 3))
    scale = arrays.get("SCALE", np.ones((count, 3)))
    matrices = np.zeros((count, 4, 4))
    matrices[:, :3, :3] = rotation * scale[:, None, :]  # R S: column j of R scaled by s_j
    matrices[:, :3, 3] = translation
    matrices[:, 3, 3] = 1.0
    return matrices


def _floats(document: dict, binary: bytes, index: int) -> np.ndarray:
    """An accessor's data as float64, normalized integers mapped to [-1, 1] as glTF defines them."""
    data = read_accessor(document, binary, index)
    if document["accessors"][index].get("normalized") and np.issubdtype(data.dtype, np.integer):
        return np.maximum(data / np.iinfo(data.dtype).max, -1.0)
    return data.astype(np.float64)


def load_glb_scene(source: bytes | str | Path):
    """trimesh.Scene of a GLB (bytes or a path; see the module docstring). An instancing node keeps its
    transform and extension metadata but no geometry; its children `<node>_instance_<k>` draw its mesh at each
    instance. A GLB without instancing loads as `trimesh.load` loads it."""
    import trimesh
    from trimesh.scene.transforms import SceneGraph

    data = source if isinstance(source, bytes) else Path(source).read_bytes()
    document, binary = read_glb_chunks(data)  # raises GlbError (a TreefarmError) on bytes that are not a GLB
    scene = trimesh.load(io.BytesIO(data), file_type="glb", force="scene")
    edges = []
    for parent, node, attr in scene.graph.to_edgelist():
        extension = (attr.get("metadata") or {}).get("gltf_extensions", {}).get(INSTANCING)
        if extension is None or attr.get("geometry") is None:
            edges.append((parent, node, attr))
            continue
        geometry = attr.pop("geometry")
        edges.append((parent, node, attr))
        matrices = instance_matrices(document, binary, extension["attributes"])
        # trimesh's graph holds one node per drawn copy: a loop over instances, not over vertices.
        edges += [(node, f"{node}_instance_{k}", {"matrix": matrix, "geometry": geometry})
                  for k, matrix in enumerate(matrices)]
    graph = SceneGraph(base_frame=scene.graph.base_frame)
    graph.from_edgelist(edges)
    return trimesh.Scene(geometry=scene.geometry, graph=graph, metadata=scene.metadata)
