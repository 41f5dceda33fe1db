"""Binary glTF 2.0 (GLB), written with struct and json so every byte is ours: the one GLB writer (`GlbWriter`,
`GlbBuffer`), a TreeMesh's GLB with it, and readers for GLB bytes.

In: a TreeMesh (Z up), or any scene built entry by entry with `GlbWriter` (the asset library's LODs, instancing
and variants, `farm.library.gltf_asset`). Out: GLB bytes (Y up); same input, same bytes.
"""
from __future__ import annotations

import json
import struct

import numpy as np

from ..errors import TreefarmError
from ..geometry.vectors import column_bounds
from .textures import bark_png, leaf_png
from ..tree_mesh import MeshPart, TreeMesh

__all__ = ["tree_mesh_to_glb", "node_matrix", "GlbBuffer", "GlbWriter", "read_glb_json", "read_glb_chunks",
           "read_accessor", "z_up_to_y_up", "Z_UP_TO_Y_UP", "GlbError", "ARRAY_BUFFER", "ELEMENT_ARRAY_BUFFER", "REPEAT",
           "CLAMP_TO_EDGE", "TRIANGLES"]

_GLB_MAGIC = 0x46546C67  # "glTF"
_CHUNK_JSON = 0x4E4F534A  # "JSON"
_CHUNK_BIN = 0x004E4942  # "BIN\0"
# Buffer view targets (vertex attributes, indices), sampler wrap modes and the triangle-list primitive mode.
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
REPEAT, CLAMP_TO_EDGE = 10497, 33071
TRIANGLES = 4
_FLOAT, _UNSIGNED_SHORT, _UNSIGNED_INT = 5126, 5123, 5125
_LINEAR, _LINEAR_MIPMAP_LINEAR = 9729, 9987
_COMPONENTS = {np.dtype(np.float32): _FLOAT, np.dtype(np.uint16): _UNSIGNED_SHORT, np.dtype(np.uint32): _UNSIGNED_INT}
# Our Z-up world (x, y, z) to glTF's Y-up frame (x, z, -y), a rotation: v_gltf = Z_UP_TO_Y_UP @ v.
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
Z_UP_TO_Y_UP.setflags(write=False)


class GlbError(TreefarmError):
    """Bytes that are not a GLB file this module can read, or an object that is not a TreeMesh."""


def z_up_to_y_up(vectors: np.ndarray) -> np.ndarray:
    """(K, 3) float32: our Z-up world (x, y, z) in glTF's Y-up frame, (x, z, -y) (`Z_UP_TO_Y_UP` applied by
    reordering, so no value is rounded). A rotation, so normals too."""
    turned = np.asarray(vectors, np.float32)[:, [0, 2, 1]]  # a new C-ordered array
    np.negative(turned[:, 2], out=turned[:, 2])
    return turned


class GlbBuffer:
    """The binary chunk of a GLB: buffer views (each padded to 4 bytes) and the accessors that read them.

    `keep_bytes=False` records the same views and accessors and counts their bytes without keeping any (for the
    exact length of a file that is not packed, `GlbWriter.glb_length`).
    """

    def __init__(self, keep_bytes: bool = True) -> None:
        self.keep_bytes = keep_bytes
        self.blobs: list[bytes] = []
        self.size = 0  # bytes of the chunk, padding included
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        """Index of a new buffer view holding `data` (`target`: ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER or None)."""
        if self.keep_bytes:
            self.blobs.append(data)
            if len(data) % 4:
                self.blobs.append(b"\0" * (-len(data) % 4))
        return self._record_view(len(data), target)

    def _record_view(self, length: int, target: int | None) -> int:
        entry = {"buffer": 0, "byteOffset": self.size, "byteLength": length}
        if target is not None:
            entry["target"] = target
        self.size += length + (-length) % 4
        self.views.append(entry)
        return len(self.views) - 1

    def accessor(self, array: np.ndarray, kind: str, target: int | None, with_bounds: bool = False) -> int:
        """Index of a new accessor over a view of `array` ((count,) or (count, width) float32, uint16 or uint32;
        `kind` "SCALAR", "VEC2", ...), with its per-component min and max when `with_bounds` (POSITION needs
        them)."""
        component = _COMPONENTS[array.dtype]
        if self.keep_bytes:
            little = np.ascontiguousarray(array).astype(array.dtype.newbyteorder("<"), copy=False)
            view = self.view(little.tobytes(), target)
        else:
            view = self._record_view(int(array.nbytes), target)
        entry = {"bufferView": view, "componentType": component, "count": int(len(array)), "type": kind}
        if with_bounds:
            low, high = column_bounds(array.reshape(len(array), -1))
            entry["min"] = [float(x) for x in low]
            entry["max"] = [float(x) for x in high]
        self.accessors.append(entry)
        return len(self.accessors) - 1

    def pieces(self) -> list[bytes]:
        """The buffer's bytes as the pieces it holds, in order (joined once, by whoever writes them)."""
        if not self.keep_bytes:
            raise TypeError("this GlbBuffer counts bytes without keeping them (keep_bytes=False)")
        return self.blobs

    def tobytes(self) -> bytes:
        return b"".join(self.pieces())


class GlbWriter:
    """One glTF 2.0 document and its binary chunk, filled entry by entry, packed by `to_glb`.

    Each adder returns the new entry's index. Vertices and normals go in Z up and are written Y up; UVs go in
    OBJ convention (v = 0 at the bottom) and are written with v flipped, as glTF reads images from the top.
    `head` (for `document`, `to_glb`, `glb_length`) is the document's first keys: "asset", "scene", "scenes"
    and any extension keys; nodes and the non-empty lists follow.
    """

    def __init__(self, keep_bytes: bool = True) -> None:
        self.buffer = GlbBuffer(keep_bytes)
        self.nodes: list[dict] = []
        self.meshes: list[dict] = []
        self.materials: list[dict] = []
        self.textures: list[dict] = []
        self.images: list[dict] = []
        self.samplers: list[dict] = []

    def texture(self, name: str, png: bytes, wrap: int) -> int:
        """A texture of an embedded PNG image named `name`, trilinear, wrapping by `wrap` (REPEAT or
        CLAMP_TO_EDGE) in both directions."""
        self.samplers.append({"magFilter": _LINEAR, "minFilter": _LINEAR_MIPMAP_LINEAR, "wrapS": wrap, "wrapT": wrap})
        self.images.append({"name": name, "bufferView": self.buffer.view(png), "mimeType": "image/png"})
        self.textures.append({"sampler": len(self.samplers) - 1, "source": len(self.images) - 1})
        return len(self.textures) - 1

    def material(self, entry: dict) -> int:
        self.materials.append(entry)
        return len(self.materials) - 1

    def mesh(self, name: str, primitive: dict) -> int:
        """A mesh of one primitive."""
        self.meshes.append({"name": name, "primitives": [primitive]})
        return len(self.meshes) - 1

    def node(self, entry: dict) -> int:
        self.nodes.append(entry)
        return len(self.nodes) - 1

    def floats(self, array: np.ndarray, kind: str, target: int | None = ARRAY_BUFFER,
               with_bounds: bool = False) -> int:
        """An accessor of `array` as float32 (`target` None for data that is not a vertex attribute, such as
        instance transforms)."""
        return self.buffer.accessor(np.ascontiguousarray(array, np.float32), kind, target, with_bounds)

    def triangles(self, vertices: np.ndarray, normals: np.ndarray, uvs: np.ndarray, faces: np.ndarray,
                  extra: dict[str, tuple[np.ndarray, str]] | None = None) -> tuple[dict[str, int], int]:
        """The accessors of a triangle mesh: (attributes {name: accessor}, indices accessor).

        vertices, normals : (V, 3) float, Z up (POSITION with bounds, NORMAL); uvs : (V, 2) float, OBJ
        convention (TEXCOORD_0); faces : (F, 3) int (indices uint16 when they fit, else uint32); extra : more
        per-vertex attributes, name -> (array (V, k), kind), written as float32 in that order after TEXCOORD_0.
        """
        uv = np.asarray(uvs, np.float32).copy()
        uv[:, 1] = 1.0 - uv[:, 1]  # glTF puts v = 0 at the top of the image
        index_type = np.uint16 if len(vertices) <= 0xFFFF else np.uint32
        attributes = {"POSITION": self.floats(z_up_to_y_up(vertices), "VEC3", with_bounds=True),
                      "NORMAL": self.floats(z_up_to_y_up(normals), "VEC3"), "TEXCOORD_0": self.floats(uv, "VEC2")}
        for name, (array, kind) in (extra or {}).items():
            attributes[name] = self.floats(array, kind)
        indices = self.buffer.accessor(np.asarray(faces).reshape(-1).astype(index_type), "SCALAR",
                                       ELEMENT_ARRAY_BUFFER)
        return attributes, indices

    def document(self, head: dict) -> dict:
        """The JSON document: `head`, the nodes, every non-empty list, and the buffer when it holds bytes."""
        document = {**head, "nodes": self.nodes}
        lists = {"meshes": self.meshes, "materials": self.materials, "textures": self.textures,
                 "images": self.images, "samplers": self.samplers, "accessors": self.buffer.accessors,
                 "bufferViews": self.buffer.views}
        document.update({key: value for key, value in lists.items() if value})
        if self.buffer.size:
            document["buffers"] = [{"byteLength": self.buffer.size}]
        return document

    def _json_chunk(self, head: dict) -> bytes:
        json_bytes = json.dumps(self.document(head), separators=(",", ":"), ensure_ascii=True).encode("ascii")
        return json_bytes + b" " * ((-len(json_bytes)) % 4)

    def to_glb(self, head: dict) -> bytes:
        """GLB bytes: header, JSON chunk (compact, ASCII, space-padded), BIN chunk when the buffer holds bytes.
        No timestamps: the same entries give the same bytes."""
        json_bytes = self._json_chunk(head)
        pieces = [struct.pack("<II", len(json_bytes), _CHUNK_JSON), json_bytes]
        if self.buffer.size:
            pieces += [struct.pack("<II", self.buffer.size, _CHUNK_BIN), *self.buffer.pieces()]
        length = 12 + sum(len(piece) for piece in pieces)
        return b"".join([struct.pack("<III", _GLB_MAGIC, 2, length), *pieces])  # one copy of the buffers

    def glb_length(self, head: dict) -> int:
        """len(self.to_glb(head)), exactly, without packing the binary chunk (works with keep_bytes=False)."""
        binary = 8 + self.buffer.size if self.buffer.size else 0
        return 12 + 8 + len(self._json_chunk(head)) + binary


def _part_primitive(writer: GlbWriter, part: MeshPart, material: int) -> dict:
    attributes, indices = writer.triangles(part.vertices, part.normals, part.uvs, part.faces)
    return {"attributes": attributes, "indices": indices, "material": material, "mode": TRIANGLES}


def node_matrix(transform) -> list[float] | None:
    """The glTF node `matrix` (16 floats, column-major, Y up) of a 4x4 `transform` in our Z-up world, or None for
    the identity (glTF's default, left out of the file).

    Vertices are written Y up (v_gltf = C v, C = Z_UP_TO_Y_UP), so the node matrix is the conjugate C T C^T:
    then M v_gltf = C (T v), the transformed point turned Y up. C is a signed permutation, so no value is
    rounded. The transform must decompose into translation, rotation and positive scale along its own axes
    (glTF requires a TRS-decomposable node matrix): bottom row (0, 0, 0, 1), orthogonal columns, determinant > 0.
    """
    try:
        matrix = np.array(transform, dtype=np.float64)
    except (TypeError, ValueError):
        raise GlbError(f"transform {transform!r} is not numeric: allowed a 4x4 matrix of finite numbers") from None
    if matrix.shape != (4, 4):
        raise GlbError(f"transform has shape {matrix.shape}: allowed a 4x4 matrix of finite numbers")
    if not np.all(np.isfinite(matrix)):
        raise GlbError(f"transform {matrix.tolist()} has NaN or infinity: allowed a 4x4 matrix of finite numbers")
    if not np.array_equal(matrix[3], [0.0, 0.0, 0.0, 1.0]):
        raise GlbError(f"transform bottom row {matrix[3].tolist()} is invalid: allowed [0, 0, 0, 1] (an affine map)")
    linear = matrix[:3, :3]
    gram = linear.T @ linear
    scale = np.sqrt(np.diag(gram))
    off_diagonal = gram - np.diag(np.diag(gram))
    if np.linalg.det(linear) <= 0 or np.abs(off_diagonal).max() > 1e-6 * scale.max() ** 2:
        raise GlbError(f"transform linear part {np.round(linear, 6).tolist()} is invalid: allowed a rotation times a "
                       "positive scale (orthogonal columns, determinant > 0), as a glTF node matrix must decompose")
    if np.array_equal(matrix, np.eye(4)):
        return None
    turn = np.eye(4)
    turn[:3, :3] = Z_UP_TO_Y_UP
    return [float(x) for x in (turn @ matrix @ turn.T).T.ravel()]


def _check_extras(extras) -> dict:
    if not isinstance(extras, dict) or not all(isinstance(key, str) for key in extras):
        raise GlbError(f"extras {extras!r:.80} is invalid: allowed a dict with string keys of JSON values")
    try:
        json.dumps(extras, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise GlbError(f"extras {extras!r:.80} is not JSON ({exc}): allowed strings, finite numbers, booleans, "
                       "None, lists and dicts") from None
    return extras


def tree_mesh_to_glb(tree: TreeMesh, transform=None, extras: dict | None = None, compress_level: int = 9) -> bytes:
    """GLB bytes for `tree`: Y up, one scene, a root node named tree.name with children "bark" and "leaves".

    Each part becomes one mesh with POSITION (with min/max), NORMAL, TEXCOORD_0 (v flipped) and indices
    (uint16 when they fit, else uint32); an empty part is left out. Materials are metallic-roughness PBR:
    bark (tiling bark texture, roughness 0.9) and leaves (texture with alpha, alphaMode MASK at 0.5,
    doubleSided). Textures are PNGs embedded in the binary chunk. No timestamps: same TreeMesh, same bytes.
    transform : optional (4, 4) float, Z up, metres: where the tree's own frame sits in the world (for example a
    scan's frame), written as the root node's `matrix` (`node_matrix`; the identity writes none).
    extras : optional JSON-able dict, the root node's `extras` (what frame the file is in, measures, ...).
    With neither, the bytes are those this function wrote before it took them.
    compress_level : the textures' zlib level (`png_bytes`: 9 the smallest, lower levels faster; same pixels).
    """
    if not isinstance(tree, TreeMesh):
        raise GlbError(f"tree_mesh_to_glb needs a TreeMesh; got {type(tree).__name__}")
    matrix = None if transform is None else node_matrix(transform)
    extras = None if extras is None else _check_extras(extras)
    writer = GlbWriter()
    root = writer.node({"name": tree.name, "children": []})
    parts = (("bark", tree.bark, bark_png(tree.bark_color, compress_level), REPEAT),
             ("leaves", tree.leaves, leaf_png(tree.leaf_color, compress_level), CLAMP_TO_EDGE))
    for name, part, png, wrap in parts:
        if part.n_faces == 0:
            continue
        material = {"name": name, "pbrMetallicRoughness": {
            "baseColorTexture": {"index": writer.texture(f"{name}_texture", png, wrap)}, "metallicFactor": 0.0,
            "roughnessFactor": 0.9 if name == "bark" else 0.7}}
        if name == "leaves":
            material.update({"alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True})
        mesh = writer.mesh(name, _part_primitive(writer, part, writer.material(material)))
        writer.nodes[root]["children"].append(writer.node({"name": name, "mesh": mesh}))
    if not writer.nodes[root]["children"]:
        del writer.nodes[root]["children"]
    if matrix is not None:
        writer.nodes[root]["matrix"] = matrix
    if extras is not None:
        writer.nodes[root]["extras"] = extras
    # The generator string predates the meshing subpackage; it is in every GLB's bytes, so it stays.
    return writer.to_glb({"asset": {"version": "2.0", "generator": "treefarm species.gltf"},
                          "scene": 0, "scenes": [{"name": tree.name, "nodes": [root]}]})


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
