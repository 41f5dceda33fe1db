"""`leaves: cutout`: each single leaf an opaque outline polygon traced once from the leaf texture's alpha and placed
on every card at once (`species.studio.leaf_cutout`), in the GLB (instanced and baked, Khronos validator clean) and
the USD (UsdValidation clean); clump cards stay alpha-tested cards. And the spec's bad input for it."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from farm.cli import main as farm_main
from farm.library.spec import LibrarySpecError, default_library_spec, parse_library_spec
from gltf_validator import assert_valid_glb
from usd_validator import assert_valid_usd
from species.errors import ParameterError
from species.studio.leaf_cutout import outline_leaves, trace_leaf_outline, triangulate_polygon
from species.studio.lod import card_clumps

SPECIES, SEED = "maple", 5  # its LOD1 and LOD2 hold single leaves and clump cards both


def _area(points: np.ndarray) -> float:
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _triangle_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    a, b, c = (points[faces[:, k]] for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


# ------------------------------------------------------------------------------------------ the outline
def test_a_non_convex_polygon_is_cut_into_k_minus_2_triangles_covering_it_once():
    ell = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 3], [0, 3]], float)  # an L: one reflex corner
    for points in (ell, ell[::-1]):
        faces = triangulate_polygon(points)
        areas = _triangle_areas(points, faces)
        assert faces.shape == (4, 3) and (areas > 0).all()  # counter-clockwise, none flat
        assert np.isclose(areas.sum(), abs(_area(points)))


def test_the_leaf_outline_is_a_few_triangles_inside_the_leaf_covering_most_of_it():
    from farm.library.asset import leaf_alphas
    from species.studio.pbr_textures import leaf_atlas

    opaque = leaf_alphas(leaf_atlas((0.2, 0.45, 0.1), 128))[0]
    outline = trace_leaf_outline(opaque)
    assert 3 <= len(outline.uvs) <= 8 and outline.n_triangles == len(outline.uvs) - 2
    # Every corner lies on an opaque texel (a traced contour point), and the polygon covers most of the leaf.
    rows = np.clip(np.round((1 - outline.uvs[:, 1]) * 128 - 0.5).astype(int), 0, 127)
    cols = np.clip(np.round(outline.uvs[:, 0] * 128 - 0.5).astype(int), 0, 127)
    assert opaque[rows, cols].all()
    assert 0.8 < abs(_area(outline.uvs)) / opaque.mean() <= 1.02
    # Wound as the cards are: every triangle faces +y of the card frame.
    points = outline.card_points
    corners = points[outline.faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (normals[:, 1] > 0).all() and np.allclose(normals[:, [0, 2]], 0, atol=1e-6)
    with pytest.raises(ParameterError, match="leaf texture alpha"):
        trace_leaf_outline(np.zeros((16, 16), bool))


def test_outline_leaves_places_the_template_on_every_chosen_card_in_its_plane():
    import species

    params = species.sample("sc_young_sapling", np.random.default_rng(2))
    part = species.build_mesh(species.grow(params, species.rng_for(params)), params).leaves
    square = np.array([[0.1, 0.0], [0.9, 0.0], [0.9, 0.5], [0.5, 1.0], [0.1, 0.5]], np.float32)
    from species.studio.leaf_cutout import LeafOutline

    outline = LeafOutline(square, triangulate_polygon(square)[:, ::-1].copy())
    chosen = np.arange(part.n_vertices // 4) % 3 != 0
    placed = outline_leaves(part, outline, chosen)
    k = len(square)
    assert placed.n_vertices == k * chosen.sum() and placed.n_faces == 3 * chosen.sum()
    corners = part.vertices.reshape(-1, 4, 3)[chosen].astype(np.float64)
    got = placed.vertices.reshape(-1, k, 3)
    # Card corner 0 + u (corner 1 - corner 0) + v (corner 3 - corner 0): the affine map of each card.
    expected = corners[:, None, 0] + square[None, :, :1] * (corners[:, None, 1] - corners[:, None, 0]) \
        + square[None, :, 1:] * (corners[:, None, 3] - corners[:, None, 0])
    np.testing.assert_allclose(got, expected, atol=1e-5)
    face_normals = np.cross(*(placed.vertices[placed.faces[:, i]] - placed.vertices[placed.faces[:, 0]]
                              for i in (1, 2)))
    vertex_normals = placed.normals[placed.faces[:, 0]]
    assert (np.einsum("ij,ij->i", face_normals, vertex_normals) > 0).all()  # wound like the card faces


# ------------------------------------------------------------------------------------------ the asset's files
@pytest.fixture(scope="module")
def cutout_asset(tmp_path_factory):
    """(asset, instanced GLB, baked GLB, USD path with its textures beside it) of one maple, `leaves: cutout`."""
    from farm.dataset.storage import Location
    from farm.library.asset import build_asset
    from farm.library.gltf_asset import asset_to_glb
    from farm.library.job import write_asset_files
    from farm.tree_chain import tree_seed
    from renderers.gl_coverage import CoverageRenderer
    from species.timing import StageTimer

    spec = parse_library_spec({"species": {SPECIES: 1}, "leaves": "cutout", "texture_size": 64,
                               "impostor_tile": 32, "formats": ["glb", "usd"]})
    folder = tmp_path_factory.mktemp("cutout")
    renderer = CoverageRenderer(64)
    try:
        asset = build_asset(SPECIES, tree_seed(SEED, 0), spec, renderer, StageTimer())
        record = write_asset_files(asset, Location.resolve(str(folder)), spec, renderer, StageTimer())
    finally:
        renderer.close()
    return (asset, (folder / record["files"]["glb"]).read_bytes(), asset_to_glb(asset, instanced=False),
            folder / record["files"]["usd"])


def test_cutout_triangles_are_the_outline_on_single_leaves_and_two_on_clump_cards(cutout_asset):
    asset = cutout_asset[0]
    t = asset.leaf_outline.n_triangles
    assert 3 <= t <= 6
    mixed = 0
    for level in asset.levels[:-1]:
        clumps = card_clumps(level.mesh.leaves)
        mixed += bool(clumps.any() and (~clumps).any())
        assert level.n_triangles == level.mesh.bark.n_faces + t * (~clumps).sum() + 2 * clumps.sum() + \
            (level.twigs.n_faces if level.twigs is not None else 0)
    assert mixed  # the test's tree exercises both kinds on one level
    assert asset.metadata()["levels"][0]["triangles"] == asset.levels[0].n_triangles


@pytest.mark.parametrize("baked", [False, True])
def test_cutout_glb_is_valid_and_its_single_leaves_are_opaque_polygons(cutout_asset, tmp_path, baked):
    from species.meshing.gltf import read_accessor, read_glb_chunks

    asset, instanced, flat, _ = cutout_asset
    data = flat if baked else instanced
    assert_valid_glb(data, tmp_path, "cutout.glb")
    document, binary = read_glb_chunks(data)
    materials = document["materials"]
    kinds = {}
    for node in document["nodes"]:
        level, kind = node["name"].rsplit("_", 2)[-2:]
        if kind not in ("leaves", "clumps"):
            continue
        primitive = document["meshes"][node["mesh"]]["primitives"][0]
        material = materials[primitive["material"]]
        if kind == "leaves":  # outline polygons: no alpha test, no blending, in every season but bare
            assert material.get("alphaMode", "OPAQUE") == "OPAQUE" and material["name"] == "leaf_cutout_summer"
            seasons = [materials[m["material"]] for m in primitive["extensions"]["KHR_materials_variants"]["mappings"]]
            assert [m.get("alphaMode", "OPAQUE") for m in seasons] == ["OPAQUE", "OPAQUE", "OPAQUE", "MASK"]
        else:
            assert material["alphaMode"] == "MASK"
        triangles = document["accessors"][primitive["indices"]]["count"] // 3
        u = read_accessor(document, binary, primitive["attributes"]["TEXCOORD_0"])[:, 0]
        assert (u <= 0.5).all() if kind == "leaves" else (u >= 0.5).all()
        copies = 1 if baked else document["accessors"][
            node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["TRANSLATION"]]["count"]
        kinds.setdefault(level, 0)
        kinds[level] += triangles * copies
    for level in asset.levels[:-1]:
        expected = level.n_triangles - level.mesh.bark.n_faces - (level.twigs.n_faces if level.twigs else 0)
        assert kinds.get(level.name, 0) == expected, level.name


def test_cutout_usd_is_valid_and_binds_opaque_leaf_materials_per_season(cutout_asset):
    from pxr import UsdGeom, UsdShade

    asset, _, _, path = cutout_asset
    stage = assert_valid_usd(path)
    root = stage.GetDefaultPrim()
    root.GetVariantSets().GetVariantSet("lod").SetVariantSelection("LOD1")
    prototypes = {p.name: p for p in UsdGeom.PointInstancer(
        stage.GetPrimAtPath(root.GetPath().AppendPath("Geom/leaves"))).GetPrototypesRel().GetTargets()}
    assert set(prototypes) == {"leaf", "clump"}
    leaf = UsdGeom.Mesh(stage.GetPrimAtPath(prototypes["leaf"]))
    assert len(leaf.GetFaceVertexCountsAttr().Get()) == asset.leaf_outline.n_triangles
    for season in ("spring", "summer", "autumn"):
        root.GetVariantSets().GetVariantSet("season").SetVariantSelection(season)
        bound = {name: UsdShade.MaterialBindingAPI(stage.GetPrimAtPath(p)).ComputeBoundMaterial()[0]
                 for name, p in prototypes.items()}
        assert bound["leaf"].GetPath().name == f"leaves_cutout_{season}"
        assert bound["clump"].GetPath().name == f"leaves_{season}"
        surface = UsdShade.Shader(stage.GetPrimAtPath(bound["leaf"].GetPath().AppendChild("surface")))
        assert not surface.GetInput("opacity") and not surface.GetInput("opacityThreshold")


# ------------------------------------------------------------------------------------------ the spec
def test_leaves_default_to_cards_and_keep_the_default_spec_digest():
    spec = default_library_spec()
    assert spec.leaves == "cards" and "leaves" not in spec.to_dict()
    cutout = parse_library_spec({"leaves": "cutout"})
    assert cutout.to_dict()["leaves"] == "cutout" and cutout.digest() != spec.digest()


def test_a_leaves_value_not_in_the_list_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    with pytest.raises(LibrarySpecError, match="'leaves'.*cards, cutout"):
        parse_library_spec({"leaves": "geometry"})
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({"species": {SPECIES: 1}, "leaves": "nanite"}))
    assert farm_main(["library", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "leaves" in err[0] and "cards, cutout" in err[0]
    assert not (tmp_path / "out").exists()
