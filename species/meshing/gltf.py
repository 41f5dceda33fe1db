"""Binary glTF 2.0 (GLB) writer for a TreeMesh, written with struct and json so every byte is ours.

In: a TreeMesh (Z up). Out: GLB bytes (Y up), two textured PBR meshes "bark" and "leaves"; same input, same bytes.
"""
from __future__ import annotations

import json
import struct

import numpy as np

from ..errors import TreefarmError
from .textures import bark_png, leaf_png
from ..tree_mesh import MeshPart, TreeMesh

__all__ = ["tree_mesh_to_glb", "read_glb_json", "read_glb_chunks", "read_accessor", "z_up_to_y_up", "GlbError"]

_GLB_MAGIC = 0x46546C67  # "glTF"
_CHUNK_JSON = 0x4E4F534A  # "JSON"
_CHUNK_BIN = 0x004E4942  # "BIN\0"
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_FLOAT, _UNSIGNED_SHORT, _UNSIGNED_INT = 5126, 5123, 5125
_LINEAR, _LINEAR_MIPMAP_LINEAR = 9729, 9987
_REPEAT, _CLAMP_TO_EDGE = 10497, 33071
_TRIANGLES = 4


class GlbError(TreefarmError):
    """Bytes that are not a GLB file this module can read, or an object that is not a TreeMesh."""


def z_up_to_y_up(vectors: np.ndarray) -> np.ndarray:
    """(K, 3) float32: our Z-up world (x, y, z) in glTF's Y-up frame, (x, z, -y). A rotation, so normals too."""
    vectors = np.asarray(vectors, np.float32)
    return np.ascontiguousarray(np.stack([vectors[:, 0], vectors[:, 2], -vectors[:, 1]], axis=1))


class _BinaryBuffer:
    """Accumulates buffer views (each 4-byte aligned) and accessors for one GLB binary chunk."""

    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.size = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def _record_view(self, length: int, target: int | None) -> int:
        entry = {"buffer": 0, "byteOffset": self.size, "byteLength": length}
        if target is not None:
            entry["target"] = target
        self.size += length + (-length) % 4
        self.views.append(entry)
        return len(self.views) - 1

    def view(self, data: bytes, target: int | None = None) -> int:
        self.blobs.append(data + b"\0" * ((-len(data)) % 4))
        return self._record_view(len(data), target)

    def _payload(self, array: np.ndarray) -> bytes:
        """What an accessor's view holds: the array's little-endian bytes (a size-only buffer counts them)."""
        return np.ascontiguousarray(array).astype(array.dtype.newbyteorder("<")).tobytes()

    def accessor(self, array: np.ndarray, kind: str, target: int, with_bounds: bool = False) -> int:
        component = {np.dtype(np.float32): _FLOAT, np.dtype(np.uint16): _UNSIGNED_SHORT,
                     np.dtype(np.uint32): _UNSIGNED_INT}[array.dtype]
        entry = {"bufferView": self.view(self._payload(array), target),
                 "componentType": component, "count": int(len(array)), "type": kind}
        if with_bounds:
            entry["min"] = [float(x) for x in array.min(axis=0)]
            entry["max"] = [float(x) for x in array.max(axis=0)]
        self.accessors.append(entry)
        return len(self.accessors) - 1

    def tobytes(self) -> bytes:
        return b"".join(self.blobs)


def _primitive(buffer: _BinaryBuffer, part: MeshPart, material: int) -> dict:
    positions = z_up_to_y_up(part.vertices)
    normals = z_up_to_y_up(part.normals)
    uvs = np.ascontiguousarray(part.uvs, np.float32).copy()
    uvs[:, 1] = 1.0 - uvs[:, 1]  # glTF puts v = 0 at the top of the image
    index_type = np.uint16 if part.n_vertices <= 0xFFFF else np.uint32
    attributes = {
        "POSITION": buffer.accessor(positions, "VEC3", _ARRAY_BUFFER, with_bounds=True),
        "NORMAL": buffer.accessor(normals, "VEC3", _ARRAY_BUFFER),
        "TEXCOORD_0": buffer.accessor(uvs, "VEC2", _ARRAY_BUFFER),
    }
    indices = buffer.accessor(part.faces.reshape(-1).astype(index_type), "SCALAR", _ELEMENT_ARRAY_BUFFER)
    return {"attributes": attributes, "indices": indices, "material": material, "mode": _TRIANGLES}


def tree_mesh_to_glb(tree: TreeMesh) -> bytes:
    """GLB bytes for `tree`: Y up, one scene, a root node named tree.name with children "bark" and "leaves".

    Each part becomes one mesh with POSITION (with min/max), NORMAL, TEXCOORD_0 (v flipped) and indices
    (uint16 when they fit, else uint32); an empty part is left out. Materials are metallic-roughness PBR:
    bark (tiling bark texture, roughness 0.9) and leaves (texture with alpha, alphaMode MASK at 0.5,
    doubleSided). Textures are PNGs embedded in the binary chunk. No timestamps: same TreeMesh, same bytes.
    """
    if not isinstance(tree, TreeMesh):
        raise GlbError(f"tree_mesh_to_glb needs a TreeMesh; got {type(tree).__name__}")
    buffer = _BinaryBuffer()
    nodes: list[dict] = [{"name": tree.name, "children": []}]
    meshes, materials, textures, images, samplers = [], [], [], [], []
    parts = (("bark", tree.bark, bark_png(tree.bark_color), _REPEAT),
             ("leaves", tree.leaves, leaf_png(tree.leaf_color), _CLAMP_TO_EDGE))
    for name, part, png, wrap in parts:
        if part.n_faces == 0:
            continue
        samplers.append({"magFilter": _LINEAR, "minFilter": _LINEAR_MIPMAP_LINEAR, "wrapS": wrap, "wrapT": wrap})
        images.append({"name": f"{name}_texture", "bufferView": buffer.view(png), "mimeType": "image/png"})
        textures.append({"sampler": len(samplers) - 1, "source": len(images) - 1})
        material = {"name": name, "pbrMetallicRoughness": {
            "baseColorTexture": {"index": len(textures) - 1}, "metallicFactor": 0.0,
            "roughnessFactor": 0.9 if name == "bark" else 0.7}}
        if name == "leaves":
            material.update({"alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True})
        materials.append(material)
        meshes.append({"name": name, "primitives": [_primitive(buffer, part, len(materials) - 1)]})
        nodes.append({"name": name, "mesh": len(meshes) - 1})
        nodes[0]["children"].append(len(nodes) - 1)
    if not nodes[0]["children"]:
        del nodes[0]["children"]
    binary = buffer.tobytes()
    document = {"asset": {"version": "2.0", "generator": "treefarm species.gltf"},
                "scene": 0, "scenes": [{"name": tree.name, "nodes": [0]}], "nodes": nodes}
    for key, value in (("meshes", meshes), ("materials", materials), ("textures", textures),
                       ("images", images), ("samplers", samplers), ("accessors", buffer.accessors),
                       ("bufferViews", buffer.views)):
        if value:
            document[key] = value
    if binary:
        document["buffers"] = [{"byteLength": len(binary)}]
    json_bytes = json.dumps(document, separators=(",", ":"), ensure_ascii=True).encode("ascii")
    json_bytes += b" " * ((-len(json_bytes)) % 4)
    chunks = struct.pack("<II", len(json_bytes), _CHUNK_JSON) + json_bytes
    if binary:
        chunks += struct.pack("<II", len(binary), _CHUNK_BIN) + binary
    return struct.pack("<III", _GLB_MAGIC, 2, 12 + len(chunks)) + chunks


def read_glb_chunks(data: bytes) -> tuple[dict, bytes]:
    """The JSON document and the binary chunk (b"" when absent) of GLB bytes; checks header and lengths."""
    if len(data) < 20:
        raise GlbError(f"GLB data has {len(data)} bytes; a GLB needs at least a 12-byte header and a chunk")
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != _GLB_MAGIC or version != 2:
        raise GlbError(f"not a glTF 2.0 binary (magic {magic:#x}, version {version}); expected glTF version 2")
    if length != len(data):
        raise GlbError(f"GLB header says {length} bytes but the data has {len(data)}")
    json_length, json_type = struct.unpack_from("<II", data, 12)
    if json_type != _CHUNK_JSON:
        raise GlbError(f"first GLB chunk has type {json_type:#x}; expected JSON ({_CHUNK_JSON:#x})")
    document = json.loads(data[20:20 + json_length].decode("utf-8"))
    offset = 20 + json_length
    binary = b""
    if offset + 8 <= len(data):
        bin_length, bin_type = struct.unpack_from("<II", data, offset)
        if bin_type != _CHUNK_BIN:
            raise GlbError(f"second GLB chunk has type {bin_type:#x}; expected BIN ({_CHUNK_BIN:#x})")
        binary = data[offset + 8:offset + 8 + bin_length]
    return document, binary


_COMPONENT_TYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
                    5126: np.float32}
_TYPE_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def read_accessor(document: dict, binary: bytes, index: int) -> np.ndarray:
    """The data of accessor `index` of a GLB's (document, binary chunk), as (count,) or (count, width) numpy
    (tightly packed views, as this project writes them; a strided view raises GlbError)."""
    accessor = document["accessors"][index]
    view = document["bufferViews"][accessor["bufferView"]]
    dtype = np.dtype(_COMPONENT_TYPES[accessor["componentType"]])
    width = _TYPE_WIDTHS[accessor["type"]]
    if view.get("byteStride", width * dtype.itemsize) != width * dtype.itemsize:
        raise GlbError(f"accessor {index} reads a strided view (byteStride {view['byteStride']}); allowed packed")
    data = np.frombuffer(binary, dtype, accessor["count"] * width,
                         view.get("byteOffset", 0) + accessor.get("byteOffset", 0))
    return data.reshape(accessor["count"], width) if width > 1 else data


def read_glb_json(data: bytes) -> dict:
    """The JSON document of GLB bytes (see `read_glb_chunks`)."""
    return read_glb_chunks(data)[0]
