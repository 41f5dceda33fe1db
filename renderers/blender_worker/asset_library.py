"""Job kinds `asset_library` (GLBs to one .blend of marked assets with previews, tags and catalogs) and
`blend_info` (list the assets of a .blend). Each asset is a collection holding one GLB's objects.

`asset_library` keys: blend (output path), assets: [{id, glb, catalog_id, preview_png (optional), tags, description,
node (optional glTF node subtree), author, license, copyright, properties (optional)}]. Result: per asset its
objects, triangles and whether the preview was generated; the .blend path and size.
"""
from __future__ import annotations

import os
import time

import bpy
import numpy as np
from mathutils import Vector

from blend_bytes import make_deterministic
from fbx import check_glb, import_checked_glb, merge_instances, subtree
from scene import JobError, mesh_objects, mesh_stats, require, reset_scene

PREVIEW_SIZE = 256  # Blender's large asset previews are 256 px
LAYOUT_GAP = 1.0  # metres between neighbouring trees when the file is opened as a scene


def _load_preview(path: str) -> tuple[int, int, np.ndarray]:
    """(width, height, (w*h*4,) float32 RGBA rows bottom to top) of a PNG fitted into PREVIEW_SIZE."""
    if not os.path.isfile(path):
        raise JobError(f"preview_png {path!r} does not exist")
    image = bpy.data.images.load(path, check_existing=False)
    try:
        width, height = image.size
        if width == 0 or height == 0:
            raise JobError(f"preview_png {path!r} is not an image Blender can read")
        scale = PREVIEW_SIZE / max(width, height)
        if scale < 1.0:
            width, height = max(1, round(width * scale)), max(1, round(height * scale))
            image.scale(width, height)
        pixels = np.empty(width * height * 4, np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    return width, height, pixels


def _material_colour(material) -> np.ndarray:
    """(4,) float32 RGBA: the mean opaque texel of the base colour texture, else the base colour value."""
    if material is None or material.node_tree is None:
        return np.array([0.5, 0.5, 0.5, 1.0], np.float32)
    for node in material.node_tree.nodes:
        # len(pixels) loads a packed image first; `has_data` stays False until something has.
        if node.type == "TEX_IMAGE" and node.image is not None and len(node.image.pixels) > 0:
            texels = np.empty(len(node.image.pixels), np.float32)
            node.image.pixels.foreach_get(texels)
            texels = texels.reshape(-1, 4)
            opaque = texels[texels[:, 3] > 0.5]
            colour = (opaque if len(opaque) else texels).mean(axis=0)
            return np.array([*colour[:3], 1.0], np.float32)
    for node in material.node_tree.nodes:
        if node.type == "BSDF_PRINCIPLED":
            return np.array([*node.inputs["Base Color"].default_value[:3], 1.0], np.float32)
    return np.array([0.5, 0.5, 0.5, 1.0], np.float32)


def _splat_preview(objects: list) -> tuple[int, int, np.ndarray]:
    """A preview drawn without a GPU: triangle centres seen from the front (looking along +Y), far to near,
    coloured by their material and shaded by depth, on a transparent square. Same input, same pixels."""
    points, colours = [], []
    for obj in mesh_objects(objects):
        mesh = obj.data
        mesh.calc_loop_triangles()
        count = len(mesh.loop_triangles)
        if count == 0:
            continue
        corners = np.empty(count * 3, np.int32)
        mesh.loop_triangles.foreach_get("vertices", corners)
        vertices = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", vertices)
        centres = vertices.reshape(-1, 3)[corners.reshape(-1, 3)].mean(axis=1)
        material_index = np.empty(count, np.int32)
        mesh.loop_triangles.foreach_get("material_index", material_index)
        matrix = np.array(obj.matrix_world, np.float32)
        centres = centres @ matrix[:3, :3].T + matrix[:3, 3]
        palette = np.stack([_material_colour(slot.material) for slot in obj.material_slots]
                           or [_material_colour(None)])
        points.append(centres)
        colours.append(palette[np.clip(material_index, 0, len(palette) - 1)])
    size = PREVIEW_SIZE
    image = np.zeros((size, size, 4), np.float32)
    if points:
        points, colours = np.concatenate(points), np.concatenate(colours)
        lo, hi = points.min(axis=0), points.max(axis=0)
        extent = max(float(hi[0] - lo[0]), float(hi[2] - lo[2]), 1e-6) * 1.08
        centre_x, centre_z = (lo[0] + hi[0]) / 2, (lo[2] + hi[2]) / 2
        cols = np.clip(((points[:, 0] - centre_x) / extent + 0.5) * (size - 1), 0, size - 2).astype(np.int64)
        rows = np.clip(((points[:, 2] - centre_z) / extent + 0.5) * (size - 1), 0, size - 2).astype(np.int64)
        depth01 = (points[:, 1] - lo[1]) / max(float(hi[1] - lo[1]), 1e-6)  # 0 nearest the viewer
        shade = (1.0 - 0.45 * depth01)[:, None]
        order = np.argsort(-depth01, kind="stable")  # far first, so nearer points overwrite them
        rgba = np.concatenate([colours[order, :3] * shade[order], np.ones((len(order), 1), np.float32)], axis=1)
        for dr in (0, 1):  # 2x2 splats close the gaps between neighbouring centres
            for dc in (0, 1):
                image[rows[order] + dr, cols[order] + dc] = rgba
    return size, size, image.reshape(-1)  # rows already run bottom to top (row 0 = lowest z)


def _set_preview(collection, width: int, height: int, pixels: np.ndarray) -> None:
    preview = collection.preview_ensure()
    preview.image_size = (width, height)
    preview.image_pixels_float.foreach_set(pixels)


def _collect(objects: list, name: str):
    """A new collection `name` holding `objects` (moved out of the scene's collections)."""
    collection = bpy.data.collections.new(name)
    for obj in objects:
        for owner in list(obj.users_collection):
            owner.objects.unlink(obj)
        collection.objects.link(obj)
    return collection


def _place(collection, objects: list, x: float) -> float:
    """Shift the asset's top objects to x (a row of trees in the opened file); the collection's instance
    offset follows, so dragging the asset in still puts the tree's base at the cursor. Returns the next x."""
    stats = mesh_stats(objects)
    if stats["bounds"] is None:
        return x
    (lo_x, _, _), (hi_x, _, _) = stats["bounds"]
    shift = x - lo_x
    chosen = set(objects)
    for obj in objects:
        if obj.parent not in chosen:
            obj.location += Vector((shift, 0.0, 0.0))
    collection.instance_offset = (shift, 0.0, 0.0)
    return x + (hi_x - lo_x) + LAYOUT_GAP


def _mark(collection, asset: dict) -> None:
    collection.asset_mark()
    data = collection.asset_data
    data.description = str(asset.get("description", ""))
    data.catalog_id = require(asset, "catalog_id")
    for key in ("author", "license", "copyright"):
        if asset.get(key):
            setattr(data, key, str(asset[key]))
    for tag in asset.get("tags", []):
        data.tags.new(str(tag), skip_if_exists=True)
    for key, value in (asset.get("properties") or {}).items():
        collection[str(key)] = value


def run(job: dict, out_dir: str) -> dict:
    blend = require(job, "blend")
    assets = require(job, "assets", list)
    if not assets:
        raise JobError("asset_library job has an empty 'assets' list: give at least one asset")
    for asset in assets:
        check_glb(require(asset, "glb"))
    reset_scene()
    # Overwriting a library must not leave `.blend1` backups in the library folder.
    bpy.context.preferences.filepaths.save_version = 0
    scene = bpy.context.scene
    rows, made, x = [], [], 0.0
    for i, asset in enumerate(assets):
        start = time.perf_counter()
        asset_id = require(asset, "id")
        if asset_id in {c.name for c in made}:
            raise JobError(f"asset id {asset_id!r} appears twice: ids in one library must be unique")
        objects = subtree(merge_instances(import_checked_glb(asset["glb"])), asset.get("node"))
        for obj in objects:  # the asset's top objects leave parents outside it, keeping their place
            if obj.parent is not None and obj.parent not in objects:
                world = obj.matrix_world.copy()
                obj.parent = None
                obj.matrix_world = world
        collection = _collect(objects, asset_id)
        made.append(collection)
        scene.collection.children.link(collection)
        for obj in objects:  # unique names in the outliner, saying which asset they belong to
            if not obj.name.startswith(asset_id):
                obj.name = f"{asset_id}:{obj.name}"
            if obj.type == "MESH":
                obj.data.name = obj.name
        x = _place(collection, objects, x)
        _mark(collection, asset)
        generated = not asset.get("preview_png")
        _set_preview(collection, *(_splat_preview(objects) if generated else _load_preview(asset["preview_png"])))
        stats = mesh_stats(objects)
        rows.append({"id": asset_id, "objects": stats["objects"], "triangles": stats["triangles"],
                     "preview_generated": generated, "seconds": time.perf_counter() - start})
        print(f"treefarm-blender: asset {i + 1}/{len(assets)} {asset_id} in {rows[-1]['seconds']:.2f} s", flush=True)
    # What the imports left outside the assets (other LODs when `node` picks one, the importer's "Orphan Nodes"
    # collections of glTF nodes outside its scene) is dropped.
    kept = {obj for collection in made for obj in collection.all_objects}
    bpy.data.batch_remove([obj for obj in bpy.data.objects if obj not in kept])
    bpy.data.batch_remove([c for c in bpy.data.collections if c not in made])
    bpy.data.orphans_purge(do_recursive=True)
    # Edit-mode selection is no part of an asset, and Blender writes `.select_edge` of joined meshes with stale
    # bytes past its end, which would make the file differ from run to run.
    for mesh in bpy.data.meshes:
        for name in [a.name for a in mesh.attributes if a.name.startswith(".select_")]:
            mesh.attributes.remove(mesh.attributes[name])
    os.makedirs(os.path.dirname(os.path.abspath(blend)) or ".", exist_ok=True)
    start = time.perf_counter()
    bpy.ops.wm.save_as_mainfile(filepath=blend, compress=False, relative_remap=False)
    make_deterministic(blend)  # the same assets give the same bytes (Blender leaves a few run-dependent ones)
    return {"blend": blend, "bytes": os.path.getsize(blend), "assets": rows,
            "save_seconds": time.perf_counter() - start, "blender_version": bpy.app.version_string}


def _plain(value):
    """An ID property as JSON-able Python (IDPropertyGroup/arrays have to_dict/to_list)."""
    for method in ("to_dict", "to_list"):
        if hasattr(value, method):
            return getattr(value, method)()
    return value


def info(job: dict, out_dir: str) -> dict:
    """Job kind `blend_info`: open a .blend; per asset (any ID type) its name, type, catalog id, tags,
    description, custom properties, preview size, whether the preview has visible pixels and its mean RGBA,
    its mesh statistics and object_count (empties included) (bounds of a
    collection as an instance of it places them, i.e. less its instance offset)."""
    path = require(job, "blend")
    if not os.path.isfile(path):
        raise JobError(f"blend {path!r} does not exist")
    bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    rows = []
    for collection_name in ("collections", "objects", "materials", "node_groups", "worlds"):
        for datablock in getattr(bpy.data, collection_name):
            if datablock.asset_data is None:
                continue
            data, preview = datablock.asset_data, datablock.preview
            size = tuple(preview.image_size) if preview is not None else (0, 0)
            visible, mean = False, None
            if size[0] * size[1]:
                pixels = np.empty(size[0] * size[1] * 4, np.float32)
                preview.image_pixels_float.foreach_get(pixels)
                pixels = pixels.reshape(-1, 4)
                visible = bool((pixels[:, 3] > 0).any() and pixels[:, :3].max() > 0)
                mean = [float(v) for v in pixels.mean(axis=0)]
            objects = list(datablock.all_objects) if collection_name == "collections" else \
                [datablock] if collection_name == "objects" else []
            stats = mesh_stats(objects)
            if collection_name == "collections" and stats["bounds"] is not None:  # as placed by an instance
                offset = list(datablock.instance_offset)
                stats["bounds"] = [[v - o for v, o in zip(corner, offset)] for corner in stats["bounds"]]
            rows.append({"name": datablock.name, "type": collection_name, "catalog_id": data.catalog_id,
                         "catalog_simple_name": data.catalog_simple_name, "tags": [t.name for t in data.tags],
                         "description": data.description, "author": data.author,
                         "preview_size": list(size), "has_preview": visible, "preview_mean_rgba": mean,
                         "properties": {k: _plain(datablock[k]) for k in datablock.keys() if not k.startswith("_")},
                         "objects": stats["objects"], "object_count": len(objects),
                         "triangles": stats["triangles"], "bounds": stats["bounds"]})
    return {"blend": path, "assets": rows, "objects": len(bpy.data.objects), "collections": len(bpy.data.collections),
            "blender_version": bpy.app.version_string}
