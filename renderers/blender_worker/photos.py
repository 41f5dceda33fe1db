"""Job kind `photos`: photo-like Cycles renders of a tree GLB (bark and leaf materials, sun and sky, ground)
from a list of cameras in the farm's convention, with a depth and a part mask per view.

Job keys: glb, cameras (list of `Camera.to_dict()`), and optional settings (see DEFAULTS).
Files per view i: view_{i:03d}.png (RGB 8-bit), view_{i:03d}_depth.png (16-bit grey; metres = value * the
view's depth_scale, 0 = sky), view_{i:03d}_mask.png (8-bit grey; 0 background or ground, 1 bark, 2 leaves).
Depth is z along the optical axis (Cycles' depth pass), like the farm's pyrender depth.
"""
from __future__ import annotations

import math
import os
import shutil
import time

import bpy
import numpy as np
from mathutils import Matrix, Vector

from cameras import CameraConversionError, blender_camera_settings
from pngio import write_grey_png
from scene import PART_INDEX, JobError, import_glb, mesh_objects, part_of, require, reset_scene

DEFAULTS = {
    "samples": 16,            # Cycles samples per pixel
    "seed": 0,                # Cycles sampling seed
    "threads": 0,             # CPU threads, 0 = all
    "denoise": False,         # OpenImageDenoise on the photo (not on depth or mask)
    "filter_width": 1.5,      # pixel filter width, pixels (depth and mask come from each pixel's first sample)
    "sun_azimuth_deg": 135.0,  # compass angle of the sun, same convention as camera azimuths
    "sun_elevation_deg": 50.0,
    "sun_strength": 4.0,      # W/m^2 of the sun lamp
    "sky_strength": 0.05,     # multiplier of the physical sky (which lights the shadows)
    "ground": True,           # a textured ground plane at z = 0
    "ground_radius": 0.0,     # metres; 0 = 25 x the tree's largest extent
    "alpha_cutout": True,     # leaf textures' alpha cuts the cards (False: whole cards, as pyrender draws them)
    "max_bounces": 4,
    "transparent_max_bounces": 32,  # stacked leaf cards need many transparent hops
    "exposure": 0.0,
}
BACKGROUND_DEPTH = 1e9  # Cycles writes ~1e10 where a ray meets nothing


def _settings(job: dict) -> dict:
    unknown = sorted(set(job) - set(DEFAULTS) - {"kind", "out_dir", "glb", "cameras"})
    if unknown:
        raise JobError(f"photos job has unknown keys {unknown}: allowed {sorted(DEFAULTS)}")
    settings = {**DEFAULTS, **{k: job[k] for k in DEFAULTS if k in job}}
    if not (isinstance(settings["samples"], int) and settings["samples"] >= 1):
        raise JobError(f"samples = {settings['samples']!r} must be an integer >= 1")
    return settings


# ---------------------------------------------------------------------------------------- materials
def _principled(material):
    for node in material.node_tree.nodes:
        if node.bl_idname == "ShaderNodeBsdfPrincipled":
            return node
    return None


def _dress_bark(material) -> None:
    """Rough, non-metallic bark with a fine procedural bump (texture for feature matching in SfM)."""
    bsdf = _principled(material)
    if bsdf is None:
        return
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf.inputs["Roughness"].default_value = 0.9
    bsdf.inputs["Metallic"].default_value = 0.0
    if not bsdf.inputs["Normal"].is_linked:
        noise = nodes.new("ShaderNodeTexNoise")
        noise.inputs["Scale"].default_value = 60.0
        noise.inputs["Detail"].default_value = 6.0
        bump = nodes.new("ShaderNodeBump")
        bump.inputs["Strength"].default_value = 0.4
        links.new(noise.outputs["Fac"], bump.inputs["Height"])
        links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])


def _dress_leaf(material, alpha_cutout: bool) -> None:
    """Leaves: the GLB's colour and alpha, plus light shining through (a translucent share).

    Output = mix(transparent, mix(principled, translucent, 0.3), alpha): the alpha the importer wired into
    the Principled BSDF moves to the outer mix so the translucent share is cut out too.
    """
    bsdf = _principled(material)
    if bsdf is None:
        return
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf.inputs["Roughness"].default_value = 0.55
    alpha_links = [link for link in links if link.to_socket == bsdf.inputs["Alpha"]]
    alpha_source = alpha_links[0].from_socket if alpha_links else None
    for link in alpha_links:
        links.remove(link)
    alpha_value = bsdf.inputs["Alpha"].default_value
    bsdf.inputs["Alpha"].default_value = 1.0
    output = next(n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    translucent = nodes.new("ShaderNodeBsdfTranslucent")
    if bsdf.inputs["Base Color"].is_linked:
        links.new(bsdf.inputs["Base Color"].links[0].from_socket, translucent.inputs["Color"])
    else:
        translucent.inputs["Color"].default_value = bsdf.inputs["Base Color"].default_value
    body = nodes.new("ShaderNodeMixShader")
    body.inputs["Fac"].default_value = 0.3
    links.new(bsdf.outputs["BSDF"], body.inputs[1])
    links.new(translucent.outputs["BSDF"], body.inputs[2])
    cut = nodes.new("ShaderNodeMixShader")
    links.new(nodes.new("ShaderNodeBsdfTransparent").outputs["BSDF"], cut.inputs[1])
    links.new(body.outputs["Shader"], cut.inputs[2])
    if alpha_cutout and alpha_source is not None:
        links.new(alpha_source, cut.inputs["Fac"])
    else:
        cut.inputs["Fac"].default_value = alpha_value if alpha_cutout else 1.0
    links.new(cut.outputs["Shader"], output.inputs["Surface"])


def _dress_tree(objects, alpha_cutout: bool) -> None:
    """Label each mesh's part (pass index = mask value) and dress its materials once."""
    done = set()
    for obj in mesh_objects(objects):
        part = part_of(obj)
        obj.pass_index = PART_INDEX[part]
        for material in obj.data.materials:
            if material is None or material.name in done or not material.node_tree:
                continue
            done.add(material.name)
            if part == "leaves":
                _dress_leaf(material, alpha_cutout)
            else:
                _dress_bark(material)


# ---------------------------------------------------------------------------------------- world
def _sun_direction(azimuth_deg: float, elevation_deg: float):
    """Unit vector toward the sun, same azimuth convention as renderers.camera.view_direction."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return (math.sin(a) * math.cos(e), -math.cos(a) * math.cos(e), math.sin(e))


def _add_sky_and_sun(scene, s: dict) -> None:
    world = bpy.data.worlds.new("sky")
    scene.world = world
    nodes, links = world.node_tree.nodes, world.node_tree.links
    nodes.clear()
    sky = nodes.new("ShaderNodeTexSky")
    sky.sky_type = "MULTIPLE_SCATTERING"
    sky.sun_disc = False  # the sun lamp below gives the direct light and crisp shadows
    sky.sun_elevation = math.radians(s["sun_elevation_deg"])
    # Blender puts the sky's sun toward (sin r, cos r, .) for sun_rotation r; ours is (sin a, -cos a, .).
    sky.sun_rotation = math.radians(-s["sun_azimuth_deg"] + 180.0)
    background = nodes.new("ShaderNodeBackground")
    background.inputs["Strength"].default_value = s["sky_strength"]
    links.new(sky.outputs["Color"], background.inputs["Color"])
    links.new(background.outputs["Background"], nodes.new("ShaderNodeOutputWorld").inputs["Surface"])

    light = bpy.data.lights.new("sun", "SUN")
    light.energy = s["sun_strength"]
    light.angle = math.radians(1.0)
    sun = bpy.data.objects.new("sun", light)
    scene.collection.objects.link(sun)
    toward = _sun_direction(s["sun_azimuth_deg"], s["sun_elevation_deg"])
    # A sun lamp shines down its local -Z: point local +Z at the sun.
    sun.rotation_euler = Vector(toward).to_track_quat("Z", "Y").to_euler()


def _add_ground(scene, radius: float) -> None:
    """A square of side 2 radius at z = 0 with mottled soil and grass colours (texture for SfM)."""
    mesh = bpy.data.meshes.new("ground")
    r = radius
    mesh.from_pydata([(-r, -r, 0.0), (r, -r, 0.0), (r, r, 0.0), (-r, r, 0.0)], [], [(0, 1, 2, 3)])
    ground = bpy.data.objects.new("ground", mesh)
    ground.pass_index = 0
    scene.collection.objects.link(ground)
    material = bpy.data.materials.new("ground")
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = _principled(material)
    bsdf.inputs["Roughness"].default_value = 1.0
    coords = nodes.new("ShaderNodeTexCoord")
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 1.5
    noise.inputs["Detail"].default_value = 10.0
    links.new(coords.outputs["Object"], noise.inputs["Vector"])
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.10, 0.08, 0.05, 1.0)
    ramp.color_ramp.elements[1].color = (0.16, 0.22, 0.07, 1.0)
    links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    mesh.materials.append(material)


# ---------------------------------------------------------------------------------------- render
def _configure_cycles(scene, s: dict) -> None:
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = s["samples"]
    cycles.use_adaptive_sampling = False
    cycles.seed = int(s["seed"])
    cycles.use_denoising = bool(s["denoise"])
    if s["denoise"]:
        cycles.denoiser = "OPENIMAGEDENOISE"
    cycles.max_bounces = int(s["max_bounces"])
    cycles.transparent_max_bounces = int(s["transparent_max_bounces"])
    cycles.filter_width = float(s["filter_width"])
    scene.render.use_persistent_data = True  # keep the BVH between the views
    scene.render.threads_mode = "FIXED" if s["threads"] else "AUTO"
    if s["threads"]:
        scene.render.threads = int(s["threads"])
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.render.dither_intensity = 0.0
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.color_depth = "8"
    scene.view_settings.exposure = float(s["exposure"])
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    layer.use_pass_object_index = True


def _pass_writer(scene, directory: str):
    """Compositor: depth and object index of each render to single-channel float EXRs in `directory`."""
    tree = bpy.data.node_groups.new("passes", "CompositorNodeTree")
    scene.compositing_node_group = tree
    layers = tree.nodes.new("CompositorNodeRLayers")
    files = tree.nodes.new("CompositorNodeOutputFile")
    files.directory = directory
    files.format.media_type = "IMAGE"
    files.format.file_format = "OPEN_EXR"
    files.format.color_depth = "32"
    files.format.color_mode = "BW"
    files.file_output_items.clear()
    for name, socket in (("depth", "Depth"), ("index", "Object Index")):
        files.file_output_items.new("FLOAT", name)
        tree.links.new(layers.outputs[socket], files.inputs[name])
    return files


def _read_exr(path: str, width: int, height: int) -> np.ndarray:
    """(H, W) float32, first channel of a single-layer EXR, rows top to bottom."""
    image = bpy.data.images.load(path, check_existing=False)
    try:
        pixels = np.empty(width * height * 4, np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    return pixels.reshape(height, width, 4)[::-1, :, 0].copy()


def _place_camera(scene, camera: dict):
    try:
        settings = blender_camera_settings(camera)
    except CameraConversionError as exc:
        raise JobError(str(exc)) from None
    data = bpy.data.cameras.new(camera.get("name", "view"))
    data.type = settings["type"]
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = settings["sensor_width"]
    data.lens = settings["lens"]
    data.ortho_scale = settings["ortho_scale"]
    data.shift_x, data.shift_y = settings["shift_x"], settings["shift_y"]
    # The photo sees ground and sky past the tree, so the clip range opens beyond the tree's near/far.
    data.clip_start = min(settings["clip_start"], 0.05)
    data.clip_end = max(settings["clip_end"], 1e4)
    obj = bpy.data.objects.new(data.name, data)
    obj.matrix_world = Matrix(settings["matrix_world"])
    scene.collection.objects.link(obj)
    scene.camera = obj
    scene.render.resolution_x, scene.render.resolution_y = settings["resolution_x"], settings["resolution_y"]
    return obj


def _encode_depth(depth: np.ndarray) -> tuple[np.ndarray, float]:
    """(H, W) metres (0 = nothing) -> uint16 and metres per unit, the largest depth at 65535."""
    depth = np.where(np.isfinite(depth) & (depth < BACKGROUND_DEPTH), depth, 0.0)
    top = float(depth.max())
    scale = top / 65535.0 if top > 0 else 1.0
    return np.round(depth / scale).astype(np.uint16), scale


def run(job: dict, out_dir: str) -> dict:
    s = _settings(job)
    cameras = require(job, "cameras", list)
    if not cameras:
        raise JobError("photos job has an empty 'cameras' list: give at least one camera")
    start = time.perf_counter()
    scene = reset_scene()
    objects = import_glb(require(job, "glb"))
    if not mesh_objects(objects):
        raise JobError(f"glb {job['glb']!r} holds no mesh")
    _dress_tree(objects, bool(s["alpha_cutout"]))
    _configure_cycles(scene, s)
    _add_sky_and_sun(scene, s)
    if s["ground"]:
        extent = max(max(abs(c) for c in obj.dimensions) for obj in mesh_objects(objects))
        _add_ground(scene, float(s["ground_radius"]) or 25.0 * extent)
    pass_dir = os.path.join(out_dir, ".passes")
    files = _pass_writer(scene, pass_dir)
    setup_seconds = time.perf_counter() - start

    views = []
    for i, camera in enumerate(cameras):
        stem = f"view_{i:03d}"
        _place_camera(scene, camera)
        files.file_name = stem + "_"
        scene.render.filepath = os.path.join(out_dir, stem + ".png")
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        render_seconds = time.perf_counter() - t0
        W, H = scene.render.resolution_x, scene.render.resolution_y
        depth = _read_exr(os.path.join(pass_dir, f"{stem}_depth.exr"), W, H)
        index = _read_exr(os.path.join(pass_dir, f"{stem}_index.exr"), W, H)
        depth_png, depth_scale = _encode_depth(depth)
        write_grey_png(os.path.join(out_dir, f"{stem}_depth.png"), depth_png)
        write_grey_png(os.path.join(out_dir, f"{stem}_mask.png"),
                       np.clip(np.round(index), 0, 255).astype(np.uint8))
        views.append({"image": f"{stem}.png", "depth": f"{stem}_depth.png", "mask": f"{stem}_mask.png",
                      "depth_scale": depth_scale, "render_seconds": render_seconds,
                      "name": camera.get("name", stem)})
        print(f"treefarm-blender: view {i + 1}/{len(cameras)} {W}x{H} in {render_seconds:.2f} s", flush=True)
    shutil.rmtree(pass_dir, ignore_errors=True)
    return {"views": views, "setup_seconds": setup_seconds, "settings": s,
            "blender_version": bpy.app.version_string}
