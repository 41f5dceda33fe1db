"""Send to library with every default format (GLB, USD, OBJ, FBX, collision, .blend): one modelling session sent
once, for real, into a fresh library (Blender through the library's worker, `.venv-blender` built by `make env`);
`farm library validate` passes and each format's file opens in a client of its own."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from farm.cli import main as farm_main
from farm.dataset.storage import Location
from farm.library import parse_library_spec
from farm.library.records import write_library_record
from farm.modelling import session as edits
from farm.modelling.library_send import send_session_to_library, SESSION_TAG
from gltf_validator import assert_valid_glb
from model_site import ring
from renderers.blender import blender_available
from renderers.blender_worker.blend_bytes import read_blocks
from required_tools import missing_tool

PRESET = "sc_round_maple"
DEFAULT_FORMATS = {"glb", "usd", "obj", "fbx", "blend", "collision"}
FBX_MAGIC = b"Kaydara FBX Binary  \x00"


@pytest.fixture(scope="module")
def sent(tmp_path_factory):
    """(library folder, the asset's record): a small session (one lobe, a trunk) sent with the default formats."""
    if not blender_available():
        missing_tool("the Blender environment (.venv-blender) is missing: run `make env`")
    library = tmp_path_factory.mktemp("library")
    spec = parse_library_spec({"name": "modelled", "species": [PRESET], "texture_size": 64, "impostor_tile": 32})
    assert set(spec.formats) == DEFAULT_FORMATS  # the defaults, unlisted: what a studio's library asks for
    write_library_record(Location.resolve(str(library)), spec)
    session = edits.new_session(PRESET, seed=7)
    session = edits.add_stroke(edits.add_stroke(session, ring(1.0, 0.6)), ring(2.0, 0.5))
    session = edits.add_branch(edits.make_lobe(session), [[0, 0, 0], [0, 0, 1.2]])
    return library, send_session_to_library(session, str(library))


def test_a_session_sent_with_every_default_format_validates_and_each_file_opens(sent, tmp_path):
    library, record = sent
    files = record["files"]
    assert record["blender"] == "written" and SESSION_TAG in record["tags"]
    assert farm_main(["library", "validate", str(library)]) == 0
    rows = json.loads((library / "catalog.json").read_text())
    assert [row["id"] for row in rows] == [record["id"]]

    assert_valid_glb((library / files["glb"]).read_bytes(), tmp_path, "model.glb")
    from pxr import Usd, UsdGeom  # usd-core: imported here, as only the USD check needs it

    stage = Usd.Stage.Open(str(library / files["usd"]))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert any(prim.IsA(UsdGeom.Mesh) for prim in stage.Traverse())
    for key in ("obj", "collision"):
        mesh = trimesh.load(library / files[key], force="mesh")
        assert len(mesh.faces) > 0 and np.all(np.isfinite(mesh.vertices)), key
    fbx = [key for key in files if key.startswith("fbx_")]
    assert sorted(fbx) == ["fbx_IMPOSTOR", "fbx_LOD0", "fbx_LOD1", "fbx_LOD2", "fbx_LOD3"]
    for key in fbx:  # Blender's importer reads them back in tests/library/test_blender_outputs.py
        data = (library / files[key]).read_bytes()
        assert data.startswith(FBX_MAGIC) and b"Vertices" in data, key
    blend = (library / "blender" / f"{PRESET}.blend").read_bytes()
    blocks = read_blocks(blend)
    assert blocks[-1].code == "ENDB" and {"OB", "ME"} <= {block.code for block in blocks}
    assert record["id"].encode() in blend  # the asset's object, by its name
