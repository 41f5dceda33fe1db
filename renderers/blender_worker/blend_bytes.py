"""Make a saved .blend byte-identical between runs (the same scene gives the same file).

What differs between two saves of the same scene by Blender 5.0, and how it is rewritten:
- block addresses (which pointers hold): they depend on what data was shared in memory when the file was saved.
  IDs are renumbered 16, 32, ... in file order, each ID's data blocks 2**40 + 16, + 32, ... (Blender needs
  data addresses unique only within their ID), and every pointer with them; a pointer that holds no block's
  address (a run-time pointer, which Blender sets to NULL when it reads the file) becomes 0;
- bytes after the terminating NUL of fixed-size strings (char arrays of 16 bytes or more), and `_pad` fields,
  left as the allocator found them: zeroed;
- `bNode.identifier`, drawn at random when a node is made (unique within its tree): 1, 2, 3, ... in file order;
- `Mesh.face_sets_color_seed`, drawn from the clock: 0;
- the order of the two vertices of a `ScrEdge` (the UI's screen edges), sorted by memory address: sorted by
  their new addresses.
Blender opens the result with the same meshes, materials, images, assets and previews.

Only the file's own SDNA (its struct catalogue, block "DNA1") is read, so this follows the layout of whatever
Blender wrote the file. It handles the blend-file header of Blender 5.0 ("BLENDER17-01v...": 8-byte pointers,
little-endian, 32-byte block headers); any other header raises ValueError and leaves the file as it was.
Pure Python and numpy: runs in the Blender worker or outside it.
"""
from __future__ import annotations

import os
import re
import struct
from dataclasses import dataclass

import numpy as np

__all__ = ["make_deterministic", "read_blocks", "Block"]

_HEADER = b"BLENDER17-01v"
_HEADER_SIZE = 17
_BHEAD = struct.Struct("<4siQQQ")  # code, SDNA index, old address, length, count


@dataclass(frozen=True)
class Block:
    code: str       # "DATA", "ME", "GLOB", "DNA1", ...
    sdna: int       # index of the struct in the SDNA
    length: int     # bytes of data
    count: int      # struct instances in the data
    offset: int     # where the data starts in the file
    address: int    # the block's address when written, which pointers to it hold


def read_blocks(data: bytes | bytearray) -> list[Block]:
    """The file's blocks, in file order, up to "ENDB"."""
    if bytes(data[:len(_HEADER)]) != _HEADER:
        raise ValueError(f"not an uncompressed Blender 5 file (header {bytes(data[:_HEADER_SIZE])!r}; "
                         f"expected {_HEADER!r}...)")
    blocks, offset = [], _HEADER_SIZE
    while offset + _BHEAD.size <= len(data):
        code, sdna, address, length, count = _BHEAD.unpack_from(data, offset)
        name = code.rstrip(b"\0").decode("latin-1")
        blocks.append(Block(name, sdna, length, count, offset + _BHEAD.size, address))
        if name == "ENDB":
            return blocks
        offset += _BHEAD.size + length
    raise ValueError("the file ends before its ENDB block: it is truncated")


def _strings(blob: bytes, start: int, count: int) -> tuple[list[str], int]:
    out = []
    for _ in range(count):
        end = blob.index(b"\0", start)
        out.append(blob[start:end].decode("latin-1"))
        start = end + 1
    return out, start


def _align4(position: int) -> int:
    return (position + 3) & ~3


def _read_sdna(blob: bytes) -> tuple[list[tuple[str, list[tuple[str, str]]]], dict[str, int]]:
    """(structs as (type, [(field type, field name)]), type sizes) of a DNA1 block."""
    if blob[:8] != b"SDNANAME":
        raise ValueError("the DNA1 block does not start with SDNANAME")
    (n_names,) = struct.unpack_from("<i", blob, 8)
    names, position = _strings(blob, 12, n_names)
    position = _align4(position) + 4  # "TYPE"
    (n_types,) = struct.unpack_from("<i", blob, position)
    types, position = _strings(blob, position + 4, n_types)
    position = _align4(position) + 4  # "TLEN"
    sizes = struct.unpack_from(f"<{n_types}h", blob, position)
    position = _align4(position + 2 * n_types) + 4  # "STRC"
    (n_structs,) = struct.unpack_from("<i", blob, position)
    position += 4
    structs = []
    for _ in range(n_structs):
        type_index, n_fields = struct.unpack_from("<hh", blob, position)
        pairs = struct.unpack_from(f"<{2 * n_fields}h", blob, position + 4)
        position += 4 + 4 * n_fields
        structs.append((types[type_index], [(types[pairs[2 * i]], names[pairs[2 * i + 1]])
                                            for i in range(n_fields)]))
    return structs, dict(zip(types, sizes))


_ARRAY = re.compile(r"\[(\d+)\]")
# DNA spells unsigned bytes "char" too: short char arrays are colours and swizzles, not strings, and so is this
# 16-byte one. Strings are at least this long (names are 64 bytes, paths 1024).
_SHORTEST_STRING = 16
_BINARY_CHAR_ARRAYS = {("IDHash", "data")}


@dataclass(frozen=True)
class _Field:
    type: str          # the field's type ("char", "float", "Object", ...), the pointee's for a pointer
    name: str          # without "*", "(*...)()" and "[n]"
    pointer: bool
    function: bool     # a function pointer
    dims: list[int]    # array dimensions ([] for a single value)
    offset: int        # bytes from the start of the struct
    element: int       # bytes per element
    count: int         # elements (the product of dims)


def _fields(fields: list[tuple[str, str]], sizes: dict[str, int]):
    """The _Field of each (type, name) of a struct, in order."""
    offset = 0
    for field_type, field_name in fields:
        dims = [int(d) for d in _ARRAY.findall(field_name)]
        pointer = field_name.startswith("*") or field_name.startswith("(*")
        element = 8 if pointer else sizes[field_type]
        count = int(np.prod(dims)) if dims else 1
        bare = field_name.lstrip("*(").split("[")[0].split(")")[0]
        yield _Field(field_type, bare, pointer, field_name.startswith("(*"), dims, offset, element, count)
        offset += element * count


@dataclass
class _Layout:
    """Where, in one struct instance, the bytes to rewrite are."""
    strings: list[tuple[int, int]]  # (offset, length) of each fixed-size string
    pads: list[tuple[int, int]]     # (offset, length) of padding fields
    id_pointers: list[int]          # offsets of pointers to ID data-blocks
    data_pointers: list[int]        # offsets of every other pointer
    size: int


def _layouts(structs, sizes) -> dict[int, _Layout]:
    by_type = {name: index for index, (name, _) in enumerate(structs)}
    # ID data-blocks (Object, Mesh, ...) are the structs that begin with an ID; pointers to them are looked up
    # among the file's IDs, every other pointer among the data of the ID it belongs to.
    ids = {"ID"} | {name for name, fields in structs if fields and fields[0] == ("ID", "id")}
    cache: dict[int, _Layout] = {}

    def layout(index: int) -> _Layout:
        if index in cache:
            return cache[index]
        strings, pads, id_pointers, data_pointers, size = [], [], [], [], 0
        for f in _fields(structs[index][1], sizes):
            size = f.offset + f.element * f.count
            if f.pointer:
                to_id = f.type in ids and not f.function
                (id_pointers if to_id else data_pointers).extend(f.offset + 8 * k for k in range(f.count))
            elif f.name.startswith("_pad"):
                pads.append((f.offset, f.element * f.count))
            elif (f.type == "char" and f.dims and f.dims[-1] >= _SHORTEST_STRING
                  and (structs[index][0], f.name) not in _BINARY_CHAR_ARRAYS):
                row = f.dims[-1]
                strings.extend((f.offset + k * row, row) for k in range(f.count // row))
            elif f.type in by_type:
                inner = layout(by_type[f.type])
                for k in range(f.count):
                    base = f.offset + k * f.element
                    strings.extend((base + o, n) for o, n in inner.strings)
                    pads.extend((base + o, n) for o, n in inner.pads)
                    id_pointers.extend(base + o for o in inner.id_pointers)
                    data_pointers.extend(base + o for o in inner.data_pointers)
        cache[index] = _Layout(strings, pads, id_pointers, data_pointers, size)
        return cache[index]

    return {index: layout(index) for index in range(len(structs))}


def _field_offset(structs, sizes, struct_name: str, field_name: str) -> int | None:
    """Byte offset of a field in a struct, None when the file's SDNA has no such field."""
    fields = next((fields for name, fields in structs if name == struct_name), [])
    return next((f.offset for f in _fields(fields, sizes) if f.name == field_name), None)


def _clean_strings(view: np.ndarray, strings: list[tuple[int, int]]) -> None:
    """Zero every byte after the first NUL of each (offset, length) string of the (count, size) instances."""
    for offset, length in strings:
        column = view[:, offset:offset + length]
        after_nul = np.cumsum(column == 0, axis=1) > 0
        column[after_nul] = 0


class _Addresses:
    """Old block addresses -> new ones: the mapping, and (sorted old, new) arrays for a vectorised lookup."""

    def __init__(self, mapping: dict[int, int]):
        self.mapping = mapping
        keys = sorted(mapping)
        self.old = np.array(keys or [0], np.uint64)
        self.new = np.array([mapping[k] for k in keys] or [0], np.uint64)

    def known(self, words: np.ndarray) -> np.ndarray:
        at = np.minimum(np.searchsorted(self.old, words), len(self.old) - 1)
        return (self.old[at] == words) & (words != 0)

    def remap(self, words: np.ndarray) -> np.ndarray:
        """Values that are no block's address (run-time pointers Blender does not read back) become 0, as reading
        the file makes them."""
        at = np.minimum(np.searchsorted(self.old, words), len(self.old) - 1)
        return np.where((self.old[at] == words) & (words != 0), self.new[at], 0).astype(np.uint64)


_NOT_ID = {"DATA", "REND", "GLOB", "TEST", "DNA1", "ENDB", "USER"}
_DATA_BASE = 1 << 40  # data addresses restart per ID from here; ID addresses count up from 16


def _scopes(blocks: list[Block]) -> tuple[list[int], _Addresses, list[_Addresses]]:
    """Per block the index of its scope (the ID whose data it is; 0 before the first ID), the IDs' new
    addresses (16, 32, ... in file order) and, per scope, its data blocks' (2**40 + 16, + 32, ... in file
    order). Blender 5 needs data addresses to be unique only within their ID, and makes them so."""
    scope_of, ids, scopes = [], {}, [{}]
    for block in blocks:
        if block.code not in _NOT_ID:
            scopes.append({})
            if block.address:
                ids.setdefault(block.address, 16 * (len(ids) + 1))
        elif block.address:
            local = scopes[-1]
            local.setdefault(block.address, _DATA_BASE + 16 * (len(local) + 1))
        scope_of.append(len(scopes) - 1)
    return scope_of, _Addresses(ids), [_Addresses(local) for local in scopes]


def make_deterministic(path: str | os.PathLike) -> int:
    """Rewrite the run-dependent bytes of the .blend at `path` in place (see the module docstring); returns how
    many bytes changed. The file is replaced atomically (written beside it, then renamed)."""
    path = os.fspath(path)
    with open(path, "rb") as f:
        original = f.read()
    data = bytearray(original)
    blocks = read_blocks(data)
    dna = next((b for b in blocks if b.code == "DNA1"), None)
    if dna is None:
        raise ValueError(f"{path!r} has no DNA1 block")
    structs, sizes = _read_sdna(bytes(data[dna.offset:dna.offset + dna.length]))
    layouts = _layouts(structs, sizes)
    names = [name for name, _ in structs]
    node_id = _field_offset(structs, sizes, "bNode", "identifier")
    seed = _field_offset(structs, sizes, "Mesh", "face_sets_color_seed")
    edge_v1 = _field_offset(structs, sizes, "ScrEdge", "v1")
    scope_of, ids, scopes = _scopes(blocks)

    buffer = np.frombuffer(data, np.uint8)  # a view: writes land in `data`
    next_node = 1
    for block, scope in zip(blocks, scope_of):
        local = scopes[scope]
        if block.address:
            header = block.offset - _BHEAD.size
            own = ids if block.code not in _NOT_ID else local
            struct.pack_into("<Q", data, header + 8, own.mapping[block.address])
        if block.code in ("DNA1", "ENDB", "TEST", "REND") or block.length == 0:
            continue  # the catalogue itself, the end, the thumbnail and the render info hold no pointers
        if block.sdna == 0:  # raw data: arrays of pointers (to IDs, or to this ID's data) are remapped
            if block.length % 8 == 0:
                words = buffer[block.offset:block.offset + block.length].view("<u8")
                if words.any():
                    for table in (ids, local):
                        if np.array_equal(table.known(words), words != 0):
                            words[:] = table.remap(words)
                            break
            continue
        layout = layouts[block.sdna]
        if layout.size == 0 or layout.size * block.count > block.length:
            continue
        view = buffer[block.offset:block.offset + layout.size * block.count].reshape(block.count, layout.size)
        _clean_strings(view, layout.strings)
        for offset, length in layout.pads:
            view[:, offset:offset + length] = 0
        # An ID pointer may hold an embedded ID (a material's node tree), which is data of its owner.
        for offsets, first, second in ((layout.id_pointers, ids, local), (layout.data_pointers, local, ids)):
            if offsets:
                columns = np.array(offsets)[:, None] + np.arange(8)
                words = np.ascontiguousarray(view[:, columns]).view("<u8")[..., 0]
                mapped = np.where(first.known(words), first.remap(words), second.remap(words))
                view[:, columns] = mapped.astype(np.uint64)[..., None].view(np.uint8)
        kind = names[block.sdna]
        for row in range(block.count):
            at = block.offset + row * layout.size
            if kind == "bNode" and node_id is not None:
                struct.pack_into("<i", data, at + node_id, next_node)
                next_node += 1
            elif kind == "Mesh" and seed is not None:
                struct.pack_into("<i", data, at + seed, 0)
            elif kind == "ScrEdge" and edge_v1 is not None:
                v1, v2 = struct.unpack_from("<QQ", data, at + edge_v1)
                struct.pack_into("<QQ", data, at + edge_v1, min(v1, v2), max(v1, v2))
    changed = int(np.count_nonzero(np.frombuffer(original, np.uint8) != buffer))
    if changed:
        temporary = f"{path}.tmp-{os.getpid()}"
        with open(temporary, "wb") as f:
            f.write(data)
        os.replace(temporary, path)
    return changed
