"""Job kinds `fbx` (GLB files to FBX files for Unity/Unreal, many in one job) and `fbx_info` (read an FBX back).

`fbx` keys: exports, a list of {glb, fbx, name (optional), node (optional: keep that glTF node's subtree),
animated (optional: the armatures and their actions too, `ANIMATED_FBX_SETTINGS`)} or {glb, fbx, nodes, names}:
several nodes' subtrees in one file, each renamed (an engine LOD group).
Result: per export the FBX path, its objects (name, part, vertices, triangles), bounds and seconds.
Also the GLB import shared with `asset_library`: checked, importer bug patched, instanced meshes merged.
"""
from __future__ import annotations

import datetime
import hashlib
import json
import os
import time

import bpy
import numpy as np

from scene import JobError, animation_stats, import_glb, mesh_stats, require, reset_scene

GLB_MAGIC = b"glTF"

# What Unity and Unreal expect: Y up, -Z forward, 1 unit = 1 m (UnitScaleFactor 100 cm), transforms baked
# into the vertices (no -90 degree X rotation on every object), no leaf bones, no animation, textures
# embedded in the file so one .fbx is the whole asset.
FBX_SETTINGS = dict(
    object_types={"MESH", "EMPTY"}, apply_unit_scale=True, apply_scale_options="FBX_SCALE_UNITS",
    global_scale=1.0, axis_forward="-Z", axis_up="Y", bake_space_transform=True, use_mesh_modifiers=True,
    mesh_smooth_type="FACE", use_triangles=False, add_leaf_bones=False, bake_anim=False,
    path_mode="COPY", embed_textures=True, use_custom_props=True,
)

# With baked skeletal wind: the armature and its action (one take, keyed on every frame, as the GLB's clip), and
# the axis change left on the root: the exporter's baked space transform is not meant for armatures.
ANIMATED_FBX_SETTINGS = dict(
    FBX_SETTINGS, object_types={"MESH", "EMPTY", "ARMATURE"}, bake_space_transform=False, bake_anim=True,
    bake_anim_use_all_bones=True, bake_anim_use_nla_strips=False, bake_anim_use_all_actions=False,
    bake_anim_force_startend_keying=True, bake_anim_step=1.0, bake_anim_simplify_factor=0.0,
)


def check_glb(path: str) -> None:
    """Raise JobError unless `path` is a file that starts with the GLB magic bytes."""
    if not os.path.isfile(path):
        raise JobError(f"glb {path!r} does not exist")
    with open(path, "rb") as f:
        magic = f.read(4)
    if magic != GLB_MAGIC:
        raise JobError(f"{path!r} is not a GLB file: it starts with {magic!r}, a binary glTF starts with b'glTF'")


class _InsertionOrderedSet(dict):
    """The two things Blender 5.0's glTF mesh importer does with a set (update, iterate), in insertion order."""

    def __init__(self, items=()) -> None:
        super().__init__((item, None) for item in items)

    def update(self, items) -> None:
        for item in items:
            self[item] = None


def _patch_gltf_importer() -> None:
    """Blender 5.0's glTF importer keeps a mesh's custom attribute names in a set but their data in a list in
    file order, then pairs them by walking the set, whose order follows this process's string hashes: with
    two custom attributes of different widths (the library's _WIND VEC4 and _WIND_PIVOT VEC3) the import
    fails in some runs and not others. Its module's `set` (used only there) becomes insertion-ordered."""
    from io_scene_gltf2.blender.imp import mesh

    mesh.set = _InsertionOrderedSet


def import_checked_glb(path: str) -> list:
    """Import a GLB into the current scene after checking it is one; the importer's complaint about a broken
    file (a RuntimeError) becomes a JobError naming the file. Returns the new objects."""
    check_glb(path)
    _patch_gltf_importer()
    try:
        return import_glb(path)
    except RuntimeError as exc:
        raise JobError(f"Blender's glTF importer could not read {path!r}: {str(exc).strip()}") from exc


def load_glb(path: str) -> list:
    """A fresh scene with the GLB imported (checked first); returns the new objects, all selectable: the
    importer puts glTF nodes outside its scene (LOD1.. under MSFT_lod) in an excluded "Orphan Nodes" collection."""
    scene = reset_scene()
    objects = import_checked_glb(path)
    visible = set(scene.view_layers[0].objects)
    for obj in objects:
        if obj not in visible:
            scene.collection.objects.link(obj)
    return objects


def subtree(objects: list, node: str | None) -> list:
    """The objects of the glTF node named `node` and everything under it; all objects when node is None."""
    if node is None:
        return list(objects)
    roots = [obj for obj in objects if obj.name == node]
    if not roots:
        raise JobError(f"node {node!r} is not in the GLB: it has {sorted(obj.name for obj in objects)}")
    return [roots[0]] + list(roots[0].children_recursive)


def renamed_subtrees(objects: list, nodes: list, names: list) -> list:
    """The subtrees (`subtree`) of several glTF nodes in one list, the top of each renamed to its entry of
    `names` and its descendants' names starting with the node's name given that prefix instead: one FBX holding
    several levels as `<id>_LOD0`, `<id>_LOD1`, ... (an engine's LOD group)."""
    if not isinstance(nodes, list) or not isinstance(names, list) or len(nodes) != len(names) or not nodes:
        raise JobError(f"nodes {nodes!r} and names {names!r} must be lists of the same, non-zero length")
    chosen = []
    for node, name in zip(nodes, names):
        part = subtree(objects, str(node))
        for obj in part:
            old = obj.name
            obj.name = str(name) + old[len(node):] if old.startswith(str(node)) else f"{name}_{old}"
            if obj.type == "MESH":
                obj.data.name = obj.name
        chosen += part
    return chosen


def _repeated_mesh(source, matrices: np.ndarray, name: str):
    """A new mesh: `source` placed by each of `matrices` ((n, 4, 4) float64, into the new mesh's space), with
    its UV maps and materials repeated; built from arrays (bpy's join of thousands of objects takes minutes)."""
    n, k = len(matrices), len(source.vertices)
    co = np.empty(k * 3, np.float64)
    source.vertices.foreach_get("co", co)
    co = co.reshape(k, 3)
    placed = np.einsum("nij,kj->nki", matrices[:, :3, :3], co) + matrices[:, None, :3, 3]
    loops = np.empty(len(source.loops), np.int32)
    source.loops.foreach_get("vertex_index", loops)
    starts = np.empty(len(source.polygons), np.int32)
    source.polygons.foreach_get("loop_start", starts)
    material_index = np.empty(len(source.polygons), np.int32)
    source.polygons.foreach_get("material_index", material_index)
    copies = np.arange(n)[:, None]
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(n * k)
    mesh.vertices.foreach_set("co", placed.astype(np.float32).ravel())
    mesh.loops.add(n * len(loops))
    mesh.loops.foreach_set("vertex_index", (loops[None, :] + k * copies).astype(np.int32).ravel())
    mesh.polygons.add(n * len(starts))
    mesh.polygons.foreach_set("loop_start", (starts[None, :] + len(loops) * copies).astype(np.int32).ravel())
    mesh.polygons.foreach_set("material_index", np.tile(material_index, n))
    for layer in source.uv_layers:
        uv = np.empty(len(source.loops) * 2, np.float32)
        layer.data.foreach_get("uv", uv)
        mesh.uv_layers.new(name=layer.name).data.foreach_set("uv", np.tile(uv, n))
    for material in source.materials:
        mesh.materials.append(material)
    mesh.update()
    return mesh


def merge_instances(objects: list) -> list:
    """Objects sharing one mesh (what the importer makes of glTF EXT_mesh_gpu_instancing: one object per
    instance) merged into one mesh object; FBX has no instancing engines read, and thousands of leaf objects
    would swamp a library. The merged object takes the place and name of the instances' parent node when
    that node holds nothing else. Returns the objects left (the same list when nothing was instanced)."""
    groups: dict = {}
    for obj in objects:
        if obj.type == "MESH":
            groups.setdefault(obj.data, []).append(obj)
    if all(len(group) < 2 for group in groups.values()):
        return list(objects)
    bpy.context.view_layer.update()  # the importer set locations; matrix_world needs an update to follow
    pointers = [obj.as_pointer() for obj in objects]  # removed objects cannot be asked anything afterwards
    removed, added = set(), []
    for source, group in groups.items():
        if len(group) < 2:
            continue
        holder = group[0].parent
        holds_only_these = holder is not None and holder.type == "EMPTY" and set(holder.children) == set(group)
        owner = holder.parent if holds_only_these else holder
        into_owner = np.linalg.inv(np.array(owner.matrix_world)) if owner is not None else np.eye(4)
        matrices = np.einsum("ij,njk->nik", into_owner, np.array([np.array(o.matrix_world) for o in group]))
        name = holder.name if holds_only_these else group[0].name
        gone = list(group) + ([holder] if holds_only_these else [])
        removed.update(obj.as_pointer() for obj in gone)
        collections = list(group[0].users_collection)
        bpy.data.batch_remove(gone)
        merged = bpy.data.objects.new(name, _repeated_mesh(source, matrices, name))
        merged.parent = owner
        for collection in collections:
            collection.objects.link(merged)
        added.append(merged)
    return [obj for obj, pointer in zip(objects, pointers) if pointer not in removed] + added


def rename(objects: list, name: str) -> None:
    """The top object of `objects` becomes `name`, the others `name_<old name>` unless their name already starts
    with `name` (FBX node names)."""
    chosen = set(objects)
    for obj in objects:
        if obj.parent not in chosen:
            obj.name = name
        elif not obj.name.startswith(name):
            obj.name = f"{name}_{obj.name}"
        if obj.type == "MESH":
            obj.data.name = obj.name


def name_textures() -> None:
    """Give packed images a file name with an extension, so the embedded FBX texture is `<name>.png`."""
    for image in bpy.data.images:
        if image.packed_file is not None and not os.path.splitext(image.filepath_raw)[1]:
            extension = {"JPEG": ".jpg"}.get(image.file_format, ".png")
            image.filepath_raw = image.name + extension


class _EpochClock:
    """Stands in for `datetime` in the FBX exporter: files carry a fixed creation time, not the clock's."""

    class datetime(datetime.datetime):
        @classmethod
        def now(cls, tz=None):
            return cls(2000, 1, 1)


def _stable_uuid(uuids, key):
    """The exporter's uid of a key from a content hash: Python's `hash()` of a str changes every process."""
    from io_scene_fbx import fbx_utils

    if isinstance(key, int) and 0 <= key < 2**63:
        return fbx_utils.UUID(key)
    uuid = int.from_bytes(hashlib.blake2b(repr(key).encode(), digest_size=8).digest(), "little") % int(1e9)
    while uuid in uuids:  # the exporter's own rule for a collision: the next free number
        uuid += 1
    return fbx_utils.UUID(uuid)


def _embedded_texture_path(image, scene_data) -> tuple[str, str]:
    """(absolute, relative) texture path written in the FBX: the bare file name for both, since the pixels are
    embedded; the exporter's own choice holds the output folder's absolute path, so bytes would depend on it."""
    name = os.path.basename(image.filepath_raw) or image.name
    return name, name


def _deterministic_exporter() -> None:
    """Same scene, same FBX bytes wherever it is written: pin the time stamp, hash keys by content, forget the
    previous file's ids, write texture names without folders."""
    from io_scene_fbx import export_fbx_bin, fbx_utils

    export_fbx_bin.datetime = _EpochClock
    export_fbx_bin._gen_vid_path = _embedded_texture_path
    fbx_utils._key_to_uuid = _stable_uuid
    fbx_utils._keys_to_uuids.clear()
    fbx_utils._uuids_to_keys.clear()


def _json_custom_props(objects: list) -> None:
    """Custom properties that hold a group (a glTF node's extras object, such as an octahedral impostor's
    layout) as JSON text: the FBX exporter writes a group as its Python repr, memory address and all."""
    for obj in objects:
        for key in list(obj.keys()):
            if hasattr(obj[key], "to_dict"):
                obj[key] = json.dumps(obj[key].to_dict(), sort_keys=True)


def export_fbx(objects: list, path: str, animated: bool = False) -> None:
    _deterministic_exporter()
    _json_custom_props(objects)
    bpy.ops.object.select_all(action="DESELECT")
    for obj in objects:
        obj.select_set(True)
    os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
    tmp = path + ".tmp.fbx"
    if animated:
        _frame_range_of_actions()
    settings = ANIMATED_FBX_SETTINGS if animated else FBX_SETTINGS
    result = bpy.ops.export_scene.fbx(filepath=tmp, use_selection=True, **settings)
    if "FINISHED" not in result or not os.path.isfile(tmp):
        raise RuntimeError(f"Blender's FBX exporter did not write {path!r} ({result})")
    os.replace(tmp, path)  # whole files only: a killed job never leaves half an FBX


def _frame_range_of_actions() -> None:
    """The scene's frame range is the actions' (the clip's keys): the exporter bakes that range."""
    ranges = [action.frame_range for action in bpy.data.actions]
    if ranges:
        scene = bpy.context.scene
        scene.frame_start = int(round(min(r[0] for r in ranges)))
        scene.frame_end = int(round(max(r[1] for r in ranges)))


def run(job: dict, out_dir: str) -> dict:
    exports = require(job, "exports", list)
    if not exports:
        raise JobError("fbx job has an empty 'exports' list: give at least one {glb, fbx}")
    rows, loaded, objects = [], None, []
    for i, item in enumerate(exports):
        if not isinstance(item, dict):
            raise JobError(f"exports[{i}] = {item!r} must be an object with keys glb, fbx")
        start = time.perf_counter()
        glb, fbx = require(item, "glb"), require(item, "fbx")
        if glb != loaded:  # several LODs of one GLB: import it once
            objects, loaded = merge_instances(load_glb(glb)), glb
            name_textures()
        if item.get("nodes") is not None:  # several levels in one file, each under its own name
            chosen = renamed_subtrees(objects, item["nodes"], item.get("names"))
        else:
            chosen = subtree(objects, item.get("node"))
        if item.get("name") and item.get("nodes") is None:
            rename(chosen, str(item["name"]))
        export_fbx(chosen, fbx, animated=bool(item.get("animated", False)))
        stats = mesh_stats(chosen)
        rows.append({"glb": glb, "fbx": fbx, "objects": stats["objects"], "triangles": stats["triangles"],
                     "bounds": stats["bounds"], "bytes": os.path.getsize(fbx),
                     "seconds": time.perf_counter() - start})
        print(f"treefarm-blender: fbx {i + 1}/{len(exports)} {os.path.basename(fbx)} "
              f"{stats['triangles']} triangles in {rows[-1]['seconds']:.2f} s", flush=True)
    return {"exports": rows, "blender_version": bpy.app.version_string}


def info(job: dict, out_dir: str) -> dict:
    """Job kind `fbx_info`: import an FBX with Blender's default settings; the `scene.mesh_stats` dictionary
    with the scene's images (`_image_row`), per material the images bound to its inputs (`_bindings`), and
    the file's LodGroup nodes (`lod_groups`)."""
    path = require(job, "fbx")
    if not os.path.isfile(path):
        raise JobError(f"fbx {path!r} does not exist")
    reset_scene()
    before = set(bpy.data.objects)
    result = bpy.ops.import_scene.fbx(filepath=path)
    if "FINISHED" not in result:
        raise JobError(f"Blender's FBX importer could not read {path!r} ({result})")
    objects = [obj for obj in bpy.data.objects if obj not in before]
    stats = mesh_stats(objects)
    stats["textures"] = sorted(image.name for image in bpy.data.images if image.has_data or image.packed_file)
    stats["images"] = [_image_row(image) for image in bpy.data.images]
    stats["bindings"] = {material.name: _bindings(material) for material in bpy.data.materials}
    stats["unit_scale"] = bpy.context.scene.unit_settings.scale_length
    stats.update(animation_stats(objects))
    stats["lod_groups"] = lod_groups(path)
    return stats


def _name(elem) -> str:
    """An object's name without the class binary FBX joins to it (`name\\x00\\x01Class`)."""
    return elem.props[1].split(b"\x00\x01")[0].decode()


def lod_groups(path: str) -> list[dict]:
    """The file's LodGroup nodes as Blender's own FBX parser reads the records (its importer turns them into
    empties): per group its name, its child nodes' names in connection order (the order engines take as the
    levels'), and its NodeAttribute's properties {name: first value}."""
    from io_scene_fbx import parse_fbx  # Blender's bundled reader: there only when bpy is

    root, _ = parse_fbx.parse(path)
    tops = {elem.id: elem for elem in root.elems}
    objects = {elem.props[0]: elem for elem in tops[b"Objects"].elems}
    links = [c.props[1:3] for c in tops[b"Connections"].elems if c.props[0] == b"OO"]
    groups = []
    for uid, elem in objects.items():
        if elem.id != b"Model" or elem.props[2] != b"LodGroup":
            continue
        attached = [objects[child] for child, parent in links if parent == uid and child in objects]
        attribute = next((e for e in attached if e.id == b"NodeAttribute" and e.props[2] == b"LodGroup"), None)
        properties = {}
        for record in (r for r in (attribute.elems if attribute is not None else ()) if r.id == b"Properties70"):
            properties.update({p.props[0].decode(): p.props[4] if len(p.props) > 4 else None
                               for p in record.elems})
        groups.append({"name": _name(elem), "children": [_name(e) for e in attached if e.id == b"Model"],
                       "attribute": attribute is not None, "properties": properties})
    return groups


def _image_row(image) -> dict:
    """An imported image: name, colour space, and the sha256 of its embedded file (None when not packed)."""
    packed = image.packed_file
    return {"name": image.name, "colorspace": image.colorspace_settings.name,
            "sha256": hashlib.sha256(packed.data).hexdigest() if packed is not None else None}


def _bindings(material) -> dict:
    """{Principled BSDF input: [image names]}: the images each linked input reads, through any nodes between
    (the importer puts a Normal Map node before Normal)."""
    if material.node_tree is None:
        return {}
    out = {}
    for bsdf in (n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"):
        for socket in (s for s in bsdf.inputs if s.is_linked):
            upstream, images = [link.from_node for link in socket.links], set()
            while upstream:  # node graphs are acyclic: this walk ends
                node = upstream.pop()
                if node.type == "TEX_IMAGE" and node.image is not None:
                    images.add(node.image.name)
                upstream += [link.from_node for s in node.inputs for link in s.links]
            if images:
                out[socket.name] = sorted(images)
    return out
