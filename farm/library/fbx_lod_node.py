"""The FBX LOD-group node that Blender's exporter cannot write, added to the file it wrote: Unreal's FBX importer
builds static mesh LODs only from such a node (a Model of type `LodGroup` with a `LodGroup` NodeAttribute), the
levels being its children in order.

In: a binary FBX holding each level as a top-level node (`<id>_LOD0`, ... as `lod_group` names them), the
group's name and the thresholds between the levels (percent of the screen height). Out: the same file with one
more Model (`LodGroup`, identity transform) whose children are those level nodes in order, its NodeAttribute
(thresholds used as percentages, every level shown by LOD), and the Definitions' counts raised to match; every
other record keeps its bytes.
"""
from __future__ import annotations

import hashlib

from .fbx_binary import FbxFile, FbxRecord, read_fbx_bytes, scalar, string, write_fbx_bytes

__all__ = ["add_lod_group_node", "NAME_SEPARATOR"]

NAME_SEPARATOR = b"\x00\x01"  # binary FBX object names are `name\x00\x01Class`
# The FBX SDK's FbxLODGroup defaults for what we do not use: no distance limits, thresholds in the group's space.
MIN_DISTANCE, MAX_DISTANCE = -100.0, 100.0
# The level Model's records the group Model copies (its own Properties70 keeps only the two below).
MODEL_RECORDS = (b"Version", b"MultiLayer", b"MultiTake", b"Shading", b"Culling")
MODEL_PROPERTIES = (b"DefaultAttributeIndex", b"InheritType")


def _top(fbx: FbxFile, name: bytes) -> FbxRecord:
    record = next((r for r in fbx.records if r.name == name), None)
    if record is None:
        raise ValueError(f"FBX has no top-level {name.decode()!r} record: not a scene Blender's exporter wrote")
    return record


def _new_id(label: str, taken: set) -> int:
    """A deterministic object id for `label` that no object of the file has (the next free one on a clash)."""
    uid = int.from_bytes(hashlib.blake2b(label.encode(), digest_size=8).digest(), "little") >> 2
    while uid in taken:
        uid += 1
    taken.add(uid)
    return uid


def _p(name: str, kind: str, label: str, *values: bytes) -> FbxRecord:
    """One Properties70 entry: name, type, label, flags, then its values."""
    return FbxRecord.make(b"P", [string(name), string(kind), string(label), string(""), *values])


def _connection(child: int, parent: int) -> FbxRecord:
    return FbxRecord.make(b"C", [string("OO"), scalar(b"L", child), scalar(b"L", parent)])


def _attribute(uid: int, group: str, levels: int, thresholds: list[float]) -> FbxRecord:
    entries = [_p("MinMaxDistance", "bool", "", scalar(b"I", 0)),
               _p("MinDistance", "double", "Number", scalar(b"D", MIN_DISTANCE)),
               _p("MaxDistance", "double", "Number", scalar(b"D", MAX_DISTANCE)),
               _p("WorldSpace", "bool", "", scalar(b"I", 0)),
               _p("ThresholdsUsedAsPercentage", "bool", "", scalar(b"I", 1))]
    entries += [_p(f"Thresholds|Level{i}", "Distance", "", scalar(b"D", float(value)), string("cm"))
                for i, value in enumerate(thresholds)]
    entries += [_p(f"DisplayLevels|Level{i}", "enum", "", scalar(b"I", 0)) for i in range(levels)]  # use LOD
    return FbxRecord.make(b"NodeAttribute", [scalar(b"L", uid), string(group.encode() + NAME_SEPARATOR
                                                                     + b"NodeAttribute"), string("LodGroup")],
                          [FbxRecord.make(b"Properties70", [], entries),
                           FbxRecord.make(b"TypeFlags", [string("LodGroup")])])


def _model(uid: int, group: str, like: FbxRecord) -> FbxRecord:
    """The group's Model, its records as the level Model `like` has them (Blender's types and values)."""
    children = []
    for record in like.children:
        if record.name in MODEL_RECORDS:
            children.append(record)
        elif record.name == b"Properties70":
            kept = [p for p in record.children if p.values()[:1] and p.values()[0] in MODEL_PROPERTIES]
            children.append(FbxRecord.make(b"Properties70", [], kept))
    return FbxRecord.make(b"Model", [scalar(b"L", uid), string(group.encode() + NAME_SEPARATOR + b"Model"),
                                     string("LodGroup")], children)


def _raise_counts(definitions: FbxRecord) -> None:
    """Definitions count the objects of each type and in all: one more Model and one more NodeAttribute."""
    def bump(record: FbxRecord, by: int) -> None:
        count = record.first(b"Count")
        if count is not None:
            count.properties, count.count = scalar(b"I", int(count.values()[0]) + by), 1

    bump(definitions, 2)
    for kind in (b"Model", b"NodeAttribute"):
        entry = next((r for r in definitions.children if r.name == b"ObjectType" and r.values() == [kind]), None)
        if entry is None:
            raise ValueError(f"FBX Definitions have no ObjectType {kind.decode()!r}")
        bump(entry, 1)


def add_lod_group_node(data: bytes, group: str, levels: list[str], thresholds: list[float]) -> bytes:
    """`data` with a LodGroup node `group` holding the top-level nodes `levels` (in that order) as its children;
    `thresholds` (one fewer than the levels) are the screen-height percentages below which each next level is
    drawn. ValueError when a level is missing, is not at the top of the scene, or the counts disagree."""
    if len(thresholds) != len(levels) - 1 or not levels:
        raise ValueError(f"{len(levels)} levels need {max(len(levels) - 1, 0)} thresholds, got {len(thresholds)}")
    fbx = read_fbx_bytes(data)
    objects, connections = _top(fbx, b"Objects"), _top(fbx, b"Connections")
    ids = {}
    for index, record in enumerate(objects.children):
        values = record.values()
        if record.name == b"Model" and len(values) > 1 and isinstance(values[1], bytes):
            ids.setdefault(values[1], []).append((values[0], index))
    found = [ids.get(name.encode() + NAME_SEPARATOR + b"Model", []) for name in levels]
    missing = [name for name, hits in zip(levels, found) if len(hits) != 1]
    if missing:
        raise ValueError(f"FBX: the levels {missing} are not each one Model of the file")
    level_ids = [hits[0][0] for hits in found]
    at_root = {i: values[1] for i, c in enumerate(connections.children)
               if (values := c.values())[:1] == [b"OO"] and values[1] in level_ids and values[2] == 0}
    if sorted(at_root.values()) != sorted(level_ids):
        raise ValueError(f"FBX: the levels {levels} are not all at the top of the scene")

    taken = {values[0] for record in objects.children if (values := record.values())[:1]
             and isinstance(values[0], int)} | {0}
    model_id, attribute_id = _new_id(f"{group}\x00Model", taken), _new_id(f"{group}\x00NodeAttribute", taken)
    first_model = min(hits[0][1] for hits in found)
    like = objects.children[found[0][0][1]]
    objects.children[first_model:first_model] = [_attribute(attribute_id, group, len(levels), thresholds),
                                                 _model(model_id, group, like)]
    first_link = min(at_root)
    kept = [c for i, c in enumerate(connections.children) if i not in at_root]
    links = [_connection(model_id, 0)] + [_connection(uid, model_id) for uid in level_ids] \
        + [_connection(attribute_id, model_id)]
    kept[first_link:first_link] = links
    connections.children = kept
    _raise_counts(_top(fbx, b"Definitions"))
    return write_fbx_bytes(fbx)
