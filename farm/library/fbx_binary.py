"""Binary FBX files as a tree of records, read and written back byte for byte, so that a file Blender's
exporter wrote can gain the records it cannot write (the engine LOD group, `lod_group`).

In: the bytes of a binary FBX (version 7100..7700; 7500 and later store offsets and counts in 64 bits). Out: an
`FbxFile` (version, top-level `FbxRecord`s, footer) and, from one, the file's bytes again: every record's end
offset worked out anew, the footer's alignment padding too. A record keeps its property list as stored (arrays
stay compressed as they were); `values()` decodes the scalar and string properties, `scalar`/`string`
encode new ones.

The layout is the public one: a 27-byte header (magic, version); then records, each its end offset, property
count, property list length, name length and name, the typed properties, its nested records closed by a null
record; the top-level list closed by a null record; then the footer.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field

__all__ = ["FBX_MAGIC", "FbxFile", "FbxRecord", "read_fbx_bytes", "write_fbx_bytes", "scalar", "string"]

FBX_MAGIC = b"Kaydara FBX Binary  \x00\x1a\x00"
HEADER_SIZE = len(FBX_MAGIC) + 4
FOOTER_ID_SIZE = 16 + 4  # the footer's id, then four zero bytes, then padding to a multiple of 16
FOOTER_TAIL_SIZE = 4 + 120 + 16  # version, zeros, closing magic

# Scalar property types: struct format.
SCALARS = {b"Y": "<h", b"C": "<?", b"I": "<i", b"F": "<f", b"D": "<d", b"L": "<q"}
ARRAYS = frozenset(b"fdlib")


@dataclass
class FbxRecord:
    """One record: its name, its property list as stored (`count` properties), nested records, and whether a
    null record closes it (every record with nested records; writers also close some empty ones)."""

    name: bytes
    properties: bytes = b""
    count: int = 0
    children: list[FbxRecord] = field(default_factory=list)
    closed: bool = False

    @classmethod
    def make(cls, name: bytes, values: list[bytes], children: list[FbxRecord] | None = None) -> FbxRecord:
        """A new record from encoded properties (`scalar`, `string`), closed when it has nested records."""
        children = list(children or [])
        return cls(name, b"".join(values), len(values), children, bool(children))

    def values(self) -> list:
        """The properties decoded: numbers and bools, bytes for strings and raw data, None for arrays."""
        out, at, data = [], 0, self.properties
        for _ in range(self.count):
            kind = data[at:at + 1]
            at += 1
            if kind in SCALARS:
                fmt = SCALARS[kind]
                out.append(struct.unpack_from(fmt, data, at)[0])
                at += struct.calcsize(fmt)
            elif kind in (b"S", b"R"):
                (size,) = struct.unpack_from("<I", data, at)
                out.append(data[at + 4:at + 4 + size])
                at += 4 + size
            elif kind and kind[0] in ARRAYS:
                _, _, size = struct.unpack_from("<III", data, at)
                out.append(None)
                at += 12 + size
            else:
                raise ValueError(f"FBX record {self.name!r}: unknown property type {kind!r} at byte {at - 1} "
                                 f"of its property list")
        return out

    def first(self, name: bytes) -> FbxRecord | None:
        """The first nested record called `name`, or None."""
        return next((child for child in self.children if child.name == name), None)


@dataclass
class FbxFile:
    version: int
    records: list[FbxRecord]
    footer: bytes  # everything after the top-level null record, as read


def scalar(kind: bytes, value) -> bytes:
    """One encoded scalar property: `kind` one of Y C I F D L."""
    return kind + struct.pack(SCALARS[kind], value)


def string(value: bytes | str) -> bytes:
    """One encoded string property (FBX joins a name and its class as `name\\x00\\x01class`)."""
    data = value.encode() if isinstance(value, str) else bytes(value)
    return b"S" + struct.pack("<I", len(data)) + data


def _layout(version: int) -> tuple[str, int]:
    """The record header's struct format (end offset, property count, property list length) and the null
    record's size."""
    fmt = "<QQQ" if version >= 7500 else "<III"
    return fmt, struct.calcsize(fmt) + 1


def _read_records(data: bytes, at: int, end: int, fmt: str, null: int) -> tuple[list[FbxRecord], int, bool]:
    """The records from `at` up to a null record or `end`; returns them, the offset after, and whether a
    null record ended them."""
    records, head = [], struct.calcsize(fmt)
    while at < end:
        stop, count, size = struct.unpack_from(fmt, data, at)
        if stop == 0:
            if data[at:at + null] != bytes(null):
                raise ValueError(f"FBX: a record at byte {at} has end offset 0 but is not a null record")
            return records, at + null, True
        name_size = data[at + head]
        name_at = at + head + 1
        props_at = name_at + name_size
        if not props_at + size <= stop <= len(data):
            raise ValueError(f"FBX: the record at byte {at} ends at {stop}, outside its file of {len(data)} "
                             f"bytes: the file is cut short or not a binary FBX")
        record = FbxRecord(data[name_at:props_at], data[props_at:props_at + size], count)
        if props_at + size < stop:
            record.children, after, record.closed = _read_records(data, props_at + size, stop, fmt, null)
            if after != stop:
                raise ValueError(f"FBX: record {record.name!r} at byte {at} should end at {stop}, its nested "
                                 f"records end at {after}")
        records.append(record)
        at = stop
    return records, at, False


def read_fbx_bytes(data: bytes) -> FbxFile:
    """Parse a binary FBX; ValueError naming what is wrong when it is not one."""
    if not data.startswith(FBX_MAGIC) or len(data) < HEADER_SIZE:
        raise ValueError(f"not a binary FBX: it starts with {bytes(data[:len(FBX_MAGIC)])!r}, a binary FBX "
                         f"with {FBX_MAGIC!r}")
    (version,) = struct.unpack_from("<I", data, len(FBX_MAGIC))
    fmt, null = _layout(version)
    records, after, closed = _read_records(data, HEADER_SIZE, len(data), fmt, null)
    if not closed:
        raise ValueError("FBX: the top-level records are not closed by a null record (the file is cut short)")
    return FbxFile(version, records, bytes(data[after:]))


def _size(record: FbxRecord, head: int, null: int) -> int:
    return (head + 1 + len(record.name) + len(record.properties)
            + sum(_size(child, head, null) for child in record.children) + (null if record.closed else 0))


def _write_records(records: list[FbxRecord], at: int, fmt: str, null: int, out: list[bytes]) -> int:
    head = struct.calcsize(fmt)
    for record in records:
        if len(record.name) > 255:
            raise ValueError(f"FBX record name {record.name[:40]!r}... is longer than 255 bytes")
        stop = at + _size(record, head, null)
        out.append(struct.pack(fmt, stop, record.count, len(record.properties)))
        out.append(bytes([len(record.name)]) + record.name + record.properties)
        inner = at + head + 1 + len(record.name) + len(record.properties)
        inner = _write_records(record.children, inner, fmt, null, out)
        if record.closed:
            out.append(bytes(null))
        at = stop
    return at


def _footer(footer: bytes, at: int) -> bytes:
    """The footer with its padding redone for where it now starts: the id and four zero bytes, then zeros up
    to the next multiple of 16 (a whole 16 when already aligned), then the tail. A footer of another shape
    stays as read."""
    if len(footer) < FOOTER_ID_SIZE + FOOTER_TAIL_SIZE:
        return footer
    pad = -(at + FOOTER_ID_SIZE) % 16 or 16
    return footer[:FOOTER_ID_SIZE] + bytes(pad) + footer[-FOOTER_TAIL_SIZE:]


def write_fbx_bytes(fbx: FbxFile) -> bytes:
    """The file's bytes; a file read and written unchanged gives its own bytes back."""
    fmt, null = _layout(fbx.version)
    out = [FBX_MAGIC, struct.pack("<I", fbx.version)]
    at = _write_records(fbx.records, HEADER_SIZE, fmt, null, out) + null
    out.append(bytes(null))
    out.append(_footer(fbx.footer, at))
    return b"".join(out)
