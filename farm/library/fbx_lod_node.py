"""The FBX LOD-group node that Blender's exporter cannot write, added to the file it wrote: Unreal's FBX importer
builds static mesh LODs only from such a node (a Model of type `LodGroup` with a `LodGroup` NodeAttribute), the
levels being its children in order.

In: a binary FBX holding each level at the top of its scene (`<id>_LOD0`, ... as `lod_group` names them), the
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
    # A Distance property carries its unit after the value; the SDK writes "cm" for percentages too.
    entries += [_p(f"Thresholds|Level{i}", "Distance", "", scalar(b"D", float(value)), string("cm"))
                for i, value in enumerate(thresholds)]
    entries += [_p(f"DisplayLevels|Level{i}", "enum", "", scalar(b"I", 0)) for i in range(levels)]  # use LOD
    return FbxRecord.make(b"NodeAttribute", [scalar(b"L", uid), string(group.encode() + NAME_SEPARATOR
                                                                     + b"NodeAttribute"), string("LodGroup")],
                          [FbxRecord.make(b"Properties70", [], entries),
                           FbxRecord.make(b"TypeFlags", [string("LodGroup")])])


def _group_model(uid: int, name: str, like: FbxRecord) -> FbxRecord:
    """A new Model of type LodGroup at identity, its records as the Model `like` has them (Blender's
    types and values)."""
    children = []
    for record in like.children:
        if record.name in MODEL_RECORDS:
            children.append(record)
        elif record.name == b"Properties70":
            kept = [p for p in record.children if p.values()[:1] and p.values()[0] in MODEL_PROPERTIES]
            children.append(FbxRecord.make(b"Properties70", [], kept))
    return FbxRecord.make(b"Model", [scalar(b"L", uid), string(name.encode() + NAME_SEPARATOR + b"Model"),
                                     string("LodGroup")], children)


def _raise_counts(definitions: FbxRecord, models: int) -> None:
    """Definitions count the objects of each type and in all: `models` more Models, one more NodeAttribute."""
    def bump(record: FbxRecord, by: int) -> None:
        count = record.first(b"Count")
        if count is not None:
            count.properties, count.count = scalar(b"I", int(count.values()[0]) + by), 1

    bump(definitions, models + 1)
    for kind, by in ((b"Model", models), (b"NodeAttribute", 1)):
        entry = next((r for r in definitions.children if r.name == b"ObjectType" and r.values() == [kind]), None)
        if entry is None:
            raise ValueError(f"FBX Definitions have no ObjectType {kind.decode()!r}")
        bump(entry, by)


def _links_to_root(connections: FbxRecord) -> dict[int, int]:
    """{object id: index in Connections} of the objects linked to the scene's root (id 0)."""
    return {values[1]: index for index, c in enumerate(connections.children)
            if (values := c.values())[:1] == [b"OO"] and len(values) > 2 and values[2] == 0}


def _roots(objects: FbxRecord, at_root: dict[int, int]) -> dict:
    """{name: (id, index in Objects)} of the Models at the top of the scene (`at_root`: `_links_to_root`)."""
    roots = {}
    for index, record in enumerate(objects.children):
        values = record.values()
        if record.name == b"Model" and len(values) > 1 and values[0] in at_root:
            roots[values[1].split(NAME_SEPARATOR)[0].decode()] = (values[0], index)
    return roots


def add_lod_group_node(data: bytes, group: str, levels: list[str], thresholds: list[float]) -> bytes:
    """`data` with a LodGroup node `group` holding the levels (in that order) as its children; `thresholds`
    (one fewer than the levels) are the screen-height percentages below which each next level is drawn.

    A level is the top-level node named as it is (an empty, or the armature of a skinned level). ValueError when
    a level has none."""
    if len(thresholds) != len(levels) - 1 or not levels:
        raise ValueError(f"{len(levels)} levels need {max(len(levels) - 1, 0)} thresholds, got {len(thresholds)}")
    fbx = read_fbx_bytes(data)
    objects, connections = _top(fbx, b"Objects"), _top(fbx, b"Connections")
    at_root = _links_to_root(connections)
    roots = _roots(objects, at_root)
    missing = [level for level in levels if level not in roots]
    if missing:
        raise ValueError(f"FBX: the levels {missing} are not nodes at the top of the scene: it has "
                         f"{sorted(roots)}")
    taken = {values[0] for record in objects.children if (values := record.values())[:1]
             and isinstance(values[0], int)} | {0}
    group_id, attribute_id = _new_id(f"{group}\x00Model", taken), _new_id(f"{group}\x00NodeAttribute", taken)
    first = min(roots[level][1] for level in levels)
    objects.children[first:first] = [_attribute(attribute_id, group, len(levels), thresholds),
                                     _group_model(group_id, group, objects.children[first])]
    level_ids = [roots[level][0] for level in levels]
    links = sorted(at_root[uid] for uid in level_ids)  # the levels' links to the scene's root, in file order
    new_links = [_connection(group_id, 0)] + [_connection(uid, group_id) for uid in level_ids]
    new_links.append(_connection(attribute_id, group_id))
    dropped = set(links)
    kept = [c for i, c in enumerate(connections.children) if i not in dropped]
    kept[links[0]:links[0]] = new_links
    connections.children = kept
    _raise_counts(_top(fbx, b"Definitions"), 1)
    return write_fbx_bytes(fbx)
