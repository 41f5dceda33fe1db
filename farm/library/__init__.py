"""The studio asset library (`farm library`): trees grown on the farm's pipeline, each packaged as an asset with
levels of detail, an impostor, wind data, collision capsules and textures, in GLB, USD, OBJ, FBX and `.blend`.

Modules, from the bottom up: `spec` (LibrarySpec), `lod_fit` and `asset` (one asset in memory), `gltf_asset`,
`usd_asset`, `fbx_binary` and `fbx_lod_node` (binary FBX records; the LodGroup node Blender cannot write),
`lod_group` (the engine LOD-group FBX), `png_cache`, `previews`, `wind_viewer` (its files),
`records` (what a library folder records), `blender_catalog` (the Blender catalogs), `catalog` (catalog,
sheets, gallery, validation) and `job` (the job);
`glb_scene` reads a library GLB back into trimesh with its instanced leaves drawn.
"""
from __future__ import annotations

from .catalog import validate_library, write_catalog
from .glb_scene import load_glb_scene
from .job import add_asset, run_library
from .records import LibraryError, read_library_spec
from .spec import LibrarySpec, LibrarySpecError, default_library_spec, load_library_spec, parse_library_spec

__all__ = ["LibrarySpec", "LibrarySpecError", "parse_library_spec", "load_library_spec", "default_library_spec",
           "run_library", "add_asset", "write_catalog", "validate_library", "LibraryError",
           "read_library_spec", "load_glb_scene"]
