"""reconstruct.from_photos and `farm reconstruct --method photos`: the conftest's ten renders to a tree, upright,
in metres and isolated from the ground; and the one-line errors."""
from __future__ import annotations

import csv
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from reconstruct.from_photos import camera_up, from_photos, ground_plane, level_and_isolate
from reconstruct import hull_growth
from reconstruct.photo_outlines import OUTLINE_SIDE, outline_views
from reconstruct.hull_growth import (DEFAULT_SPECIES, aimed_bounds, crown_base_from_masks, ground_sightlines, grow_in_hull_space,
                                     photo_views, rerooted, triangulated_foot, trunk_foot, trunk_radius_from_masks)
from reconstruct.qsm import BREAST_HEIGHT_M
from reconstruct.sfm import PhotoError, SfmPoints, SfmSettings, align_to_cameras, known_cameras, sfm_points
from reconstruct.visual_hull import PinholeView
from renderers import ViewRenderer
from renderers.blender import load_view
from renderers.camera import Camera, look_at as look_at_matrix
from scipy import ndimage
from species.colonization import VoxelSpace, grow_in_space, validate
from species.presets import get_preset
from species.skeleton import Skeleton
from species.meshing.gltf import read_glb_json

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gltf_validator import assert_valid_glb  # noqa: E402

FARM = [sys.executable, "-m", "farm.cli", "reconstruct"]


@pytest.fixture(scope="module")
def posed(photos):
    return from_photos(photos.cameras_json.parent, settings=SfmSettings(threads=1), frame="scan")


def test_known_poses_give_the_tree_alone_where_the_renderer_put_it(photos, photo_tree, posed):
    record = posed.scan.provenance["sfm"]
    assert record["poses"] == "known" and record["scale"] == "cameras.json" and record["registered"] == 10
    counts = list(record["points"].values())
    assert counts == sorted(counts, reverse=True) and counts[-1] >= 100
    # most of what SfM finds on a textured ground is ground; it all goes
    assert record["points"]["ground"] < 0.5 * record["points"]["sfm"]
    # the isolated points are the tree's: in every render they land on its pixels (mask 1 bark, 2 leaves)
    world = posed.scan.cloud.to_scan_frame(posed.scan.cloud.points)
    on_tree = []
    for k, camera in enumerate(photos.cameras):
        mask = load_view(photos, k)["mask"]
        grown = mask.copy()
        for axis in (0, 1):
            for shift in (-2, -1, 1, 2):
                grown = np.maximum(grown, np.roll(mask, shift, axis=axis))
        uv, z = camera.project(world)
        col, row = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
        inside = (z > 0) & (row >= 0) & (row < camera.height) & (col >= 0) & (col < camera.width)
        on_tree.append(grown[row[inside], col[inside]] > 0)
    # the isolation steps raise the share well above that of all the SfM points above the ground band (SIFT on
    # 320 px renders of leaves triangulates many false matches in the air: docs/reconstruct.md gives both)
    assert np.concatenate(on_tree).mean() > 0.4
    # the tree stands where the generated one does: its points centred on the trunk, its height in range
    true, _ = photo_tree
    # (loosely: ten photos on a 90 degree arc see one side of the crown best)
    assert np.linalg.norm(np.median(world[:, :2], axis=0) - true.positions[0, :2]) < 0.8
    assert 0.5 * true.height < posed.scan.cloud.height + posed.scan.cloud.offset[2] < 1.1 * true.height


def test_the_glb_says_photos_and_passes_the_validator(posed, tmp_path):
    out = tmp_path / "tree.glb"
    posed.write(out, skeleton_ply=tmp_path / "tree.ply", branches_csv=tmp_path / "tree.csv")
    assert_valid_glb(out.read_bytes(), tmp_path)
    document = read_glb_json(out.read_bytes())
    treefarm = next(node for node in document["nodes"] if "extras" in node)["extras"]["treefarm"]
    assert treefarm["method"] == "photos" and treefarm["frame"] == "scan" and treefarm["sfm"]["poses"] == "known"
    assert (tmp_path / "tree.ply").is_file() and (tmp_path / "tree.csv").read_text().startswith("id,")


def test_the_outlines_from_the_photos_cameras_cover_their_tree_masks(photos, posed):
    renderer = ViewRenderer(OUTLINE_SIDE)
    mesh = posed.mesh
    away = dataclasses.replace(posed, mesh=dataclasses.replace(
        mesh, bark=dataclasses.replace(mesh.bark, vertices=mesh.bark.vertices + [100.0, 0.0, 0.0]),
        leaves=dataclasses.replace(mesh.leaves, vertices=mesh.leaves.vertices + [100.0, 0.0, 0.0])))
    try:
        drawn = outline_views(posed, photos.cameras_json.parent, renderer)
        missed = outline_views(away, photos.cameras_json.parent, renderer)
    finally:
        renderer.close()
    assert [name for name, _, _ in drawn] == [name for name, _ in posed.maps["cameras"]] and len(drawn) == 10
    assert all(image.shape == (OUTLINE_SIDE, OUTLINE_SIDE, 3) for _, image, _ in drawn)
    covered = np.array([share for _, _, share in drawn])
    assert ((covered >= 0) & (covered <= 1)).all() and np.median(covered) > 0.6
    assert all(share == 0.0 for _, _, share in missed)       # a tree 100 m off covers none of the photos' trees
    # the outline is drawn in red where the tree is, and nowhere on a tree it misses
    red = lambda image: ((image[..., 0] > 200) & (image[..., 1] < 80) & (image[..., 2] < 80)).sum()  # noqa: E731
    assert all(red(image) > 50 for _, image, _ in drawn) and all(red(image) == 0 for _, image, _ in missed)


def test_photos_alone_come_out_the_given_height_tall_and_upright(photos, bare_photos, photo_tree):
    true, _ = photo_tree
    sfm = sfm_points(bare_photos, SfmSettings(threads=1))
    tree = level_and_isolate(sfm, true.height, np.random.default_rng(0), metric=False)
    assert sfm.poses == "estimated" and tree.scale_source == "height" and tree.up_source == "ground plane"
    # scaled so the isolated tree's top is the given height above the ground plane under it
    assert tree.ground_z == 0.0 and tree.points[:, 2].max() == pytest.approx(true.height, rel=1e-6)
    # upright: the levelled up, carried into the renders' world by the cameras' own alignment, is +Z
    aligned, _ = align_to_cameras(sfm, known_cameras(photos.cameras_json.parent, sfm.registered))
    rotation = aligned.camera_rotations[0].T @ sfm.camera_rotations[0]
    assert (rotation @ tree.up)[2] > np.cos(np.radians(5.0))
    # the hull's tree is scaled so the hull, the tree's outline, is the given height (the points' top may be stray)
    grown = from_photos(bare_photos, height=true.height, settings=SfmSettings(threads=1), sfm=sfm)
    hull = grown.maps["hull"]
    assert hull.top() == pytest.approx(true.height, abs=hull.voxel_size)
    assert grown.skeleton.height == pytest.approx(true.height, rel=0.1)
    # with no height, the cameras' height above the ground plane scales the tree: at the renders' own camera
    # height it comes out about as tall as it is (the ground plane and the isolated top both err a little)
    standing = float(np.median([camera.position[2] for camera in photos.cameras])) - float(true.positions[0, 2])
    levelled = level_and_isolate(sfm, None, np.random.default_rng(0), metric=False, camera_height=standing)
    centres = sfm.camera_centres @ levelled.model_to_upright[:3, :3].T + levelled.model_to_upright[:3, 3]
    assert levelled.scale_source == "camera height" and levelled.ground_z == 0.0
    assert float(np.median(centres[:, 2])) == pytest.approx(standing, rel=1e-3)   # about the tree's ground
    assert levelled.points[:, 2].max() == pytest.approx(true.height, rel=0.15)
    # from_photos warns that the scale is the cameras' height's (the default 1.5 m: these cameras stand higher)
    guessed = from_photos(bare_photos, settings=SfmSettings(threads=1), sfm=sfm, shape="sparse")
    assert guessed.scan.provenance["sfm"]["scale"] == "camera height"
    assert any(w.startswith("no height given: the tree is scaled so that the cameras stand 1.5 m above the ground")
               for w in guessed.warnings)
    # and where SfM matched nothing on the ground (no plane), the cameras stand that high above the trunk's foot
    # the masks show
    on_tree = _kept(sfm, aligned.points[:, 2] > 0.3)
    footed = from_photos(bare_photos, settings=SfmSettings(threads=1), sfm=on_tree, camera_height=standing,
                         completion=False)
    record = footed.scan.provenance["sfm"]
    assert record["up"] == "camera up" and record["scale"] == "camera height"
    assert footed.skeleton.height == pytest.approx(true.height, rel=0.15)
    assert footed.maps["hull"].top() == pytest.approx(true.height, rel=0.15)


def test_an_unscaled_model_with_no_ground_under_it_is_refused():
    # points in a blob, no plane among them: neither a height, cameras.json nor a ground plane gives a scale
    rng = np.random.default_rng(1)
    points = rng.normal(0.0, 1.0, (400, 3)) + [0.0, 0.0, 5.0]
    centres = np.array([[10.0 * np.cos(a), 10.0 * np.sin(a), 1.5] for a in np.linspace(0, 2 * np.pi, 8, False)])
    rotations = np.array([np.array([[-np.sin(a), np.cos(a), 0.0], [0.0, 0.0, -1.0], [-np.cos(a), -np.sin(a), 0.0]])
                          for a in np.linspace(0, 2 * np.pi, 8, False)])
    sfm = SfmPoints(points, np.full((400, 3), 120, np.uint8), np.full(400, 3), [f"{k}.png" for k in range(8)], 8,
                    "estimated", 0.5, centres, rotations, np.full(8, 0.5), {})
    with pytest.raises(PhotoError, match="scale is unknown .*no ground plane.*allowed a tree height in metres"):
        level_and_isolate(sfm, None, rng, metric=False)
    with pytest.raises(PhotoError, match="camera height 0 is invalid: allowed a number of metres > 0"):
        level_and_isolate(sfm, None, rng, metric=False, camera_height=0)


def _kept(sfm: SfmPoints, keep: np.ndarray) -> SfmPoints:
    """`sfm` with only the points `keep` (N,) bool and their tracks, renumbered."""
    index = np.cumsum(keep) - 1
    tracks = sfm.observations[keep[sfm.observations[:, 0]]]
    return dataclasses.replace(sfm, points=sfm.points[keep], colours=sfm.colours[keep],
                               track_length=sfm.track_length[keep],
                               observations=np.column_stack([index[tracks[:, 0]], tracks[:, 1]]))


def _ground_only(sfm: SfmPoints) -> SfmPoints:
    """`sfm` with only its points near the ground (z < 0.3 m at known poses) and their tracks: SfM that found
    nothing on the tree, as on a phone's photos of a tree against the sky."""
    return _kept(sfm, sfm.points[:, 2] < 0.3)


def test_a_tree_sfm_found_no_points_on_is_carved_where_the_photos_aim(photos, photo_tree):
    folder = photos.cameras_json.parent
    thin = _ground_only(sfm_points(folder, SfmSettings(threads=1)))
    with pytest.raises(PhotoError, match="lie on the ground or outside the photos' footprint"):
        from_photos(folder, settings=SfmSettings(threads=1), shape="sparse", sfm=thin)
    true, _ = photo_tree
    grown = from_photos(folder, settings=SfmSettings(threads=1), sfm=thin, frame="scan")
    assert any(w.startswith("SfM left 0 points on the tree: its place and size are the photos' outlines'")
               for w in grown.warnings)
    # the tree stands on its true root and is about as tall (known poses: metres), grown in the hull (ten photos
    # on a 90 degree arc bound the top loosely: the hull the points bound is 5 % too tall, this one 11 %)
    root = grown.scan.transform[:3, 3]
    assert np.linalg.norm(root[:2] - true.positions[0, :2]) < 0.1 * true.height
    assert grown.maps["hull"].top() == pytest.approx(true.height, rel=0.15)
    assert grown.skeleton.height == pytest.approx(true.height, rel=0.15) and "main_skeleton" in grown.maps
    # a height given scales it to that height, the hull's top there
    scaled = from_photos(folder, height=2.0 * true.height, settings=SfmSettings(threads=1), sfm=thin)
    assert scaled.maps["hull"].top() == pytest.approx(2.0 * true.height, abs=scaled.maps["hull"].voxel_size)


def test_with_no_ground_plane_the_tree_stands_on_the_foot_the_masks_show(photos, photo_tree):
    # SfM matched nothing on the ground, and a few false matches lie 3 m under it: the lowest point is no ground
    folder = photos.cameras_json.parent
    sfm = sfm_points(folder, SfmSettings(threads=1))
    above = _kept(sfm, sfm.points[:, 2] > 0.3)
    false = np.random.default_rng(0).normal([0.0, 0.0, -3.0], 0.2, (5, 3))
    thin = dataclasses.replace(above, points=np.concatenate([above.points, false]),
                               colours=np.concatenate([above.colours, np.full((5, 3), 100, np.uint8)]),
                               track_length=np.concatenate([above.track_length, np.full(5, 3)]))
    grown = from_photos(folder, settings=SfmSettings(threads=1), sfm=thin, frame="scan", completion=False)
    assert grown.scan.provenance["sfm"]["up"] == "cameras.json"          # no plane was found
    said = [w for w in grown.warnings
            if w.startswith("SfM found no ground plane: the ground is where the photos' masks show the trunk's foot")]
    # in metres: the false points lie 3 m (0.2 m spread) under the ground, the foot within 0.3 m of it
    assert len(said) == 1 and said[0].endswith("m over the lowest SfM point")
    assert 2.5 <= float(said[0].split("foot, ")[1].split(" m ")[0]) <= 4.0
    true, _ = photo_tree
    # where the rays through the masks' trunk bottoms meet (cast on a ground a little off, eye-height rays land
    # metres away: 5.4 m on the phone walk, 0.13 m where they meet)
    assert np.linalg.norm(grown.scan.transform[:3, 3] - true.positions[0]) < 0.3
    assert grown.maps["hull"].origin[2] > -0.5 and grown.skeleton.height == pytest.approx(true.height, rel=0.15)


def test_aimed_bounds_reach_round_the_aim_and_up_to_the_photos_top_edges():
    # eight cameras 20 m round the origin at 1.5 m, pitched 20 degrees up, 60 degrees of view up and down
    views = []
    for a in np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False):
        eye = np.array([20.0 * np.cos(a), 20.0 * np.sin(a), 1.5])
        target = np.array([0.0, 0.0, 1.5 + 20.0 * np.tan(np.radians(20.0))])
        camera = Camera(100, 100, [[50.0 / np.tan(np.radians(30.0)), 0, 49.5], [0, 50.0 / np.tan(np.radians(30.0)),
                                                                              49.5], [0, 0, 1]],
                        look_at_matrix(eye, target))
        views.append(PinholeView.from_camera(camera))
    bounds = aimed_bounds(views, np.zeros(3), 0.0)
    assert np.allclose(bounds[0], [-18.0, -18.0, 0.0]) and np.allclose(bounds[1, :2], [18.0, 18.0])
    assert bounds[1, 2] == pytest.approx(1.5 + 20.0 * np.tan(np.radians(50.0)), rel=1e-6)


def test_a_hull_no_crown_grows_in_leaves_the_sparse_tree_with_a_warning(photos, monkeypatch):
    folder = photos.cameras_json.parent
    sfm = sfm_points(folder, SfmSettings(threads=1))
    sparse = from_photos(folder, settings=SfmSettings(threads=1), shape="sparse", sfm=sfm)
    monkeypatch.setattr(hull_growth, "grow_in_hull_space", lambda params, rng, occupancy, space, guide, il: guide)
    starved = from_photos(folder, settings=SfmSettings(threads=1), shape="hull", sfm=sfm)
    assert any("no crown grew in: this is the sparse points' tree" in w for w in starved.warnings)
    assert starved.skeleton.positions.tobytes() == sparse.skeleton.positions.tobytes()
    assert "hull" in starved.maps and "main_skeleton" not in starved.maps


def _crown_over_the_top(draw):
    """`draw_masks` whose masks are the tree up to the photo's top edge over the columns the tree spans: photos
    taken under a crown that hides its top (eye height near a wide crown)."""
    def drawn(*args, **kwargs):
        masks = draw(*args, **kwargs)
        out = []
        for mask in masks:
            filled = mask.copy()
            rows, columns = np.nonzero(mask)
            if len(rows):
                filled[:rows.min(), columns.min():columns.max() + 1] = True
            out.append(filled)
        return out
    return drawn


def test_a_crown_top_no_photo_sees_is_cut_at_the_height_or_the_species_proportion(photos, photo_tree,
                                                                                    monkeypatch):
    folder = photos.cameras_json.parent
    true, _ = photo_tree
    sfm = sfm_points(folder, SfmSettings(threads=1))
    seen = from_photos(folder, settings=SfmSettings(threads=1), sfm=sfm, completion=False)
    assert not hull_growth.top_unseen(seen.maps["hull"])
    monkeypatch.setattr(hull_growth, "draw_masks", _crown_over_the_top(hull_growth.draw_masks))
    # known poses and a height: the hull is cut there, the cameras' metres (and so the crown's width) kept
    cut = from_photos(folder, height=0.8 * true.height, settings=SfmSettings(threads=1), sfm=sfm, completion=False)
    hull = cut.maps["hull"]
    assert any(w.startswith("no photo shows the crown's top") and "cut at the height given" in w
               for w in cut.warnings)
    assert cut.scan.provenance["sfm"]["scale"] == "cameras.json" and cut.scan.provenance["sfm"]["scale_factor"] == 1.0
    assert hull.top() - hull.origin[2] == pytest.approx(0.8 * true.height, abs=hull.voxel_size)
    assert hull_growth.crown_width(hull) == pytest.approx(hull_growth.crown_width(seen.maps["hull"]),
                                                          abs=2 * hull.voxel_size)
    # no height: the species' height for the crown's width
    guessed = from_photos(folder, settings=SfmSettings(threads=1), sfm=sfm, completion=False,
                          species="sc_broad_oak")
    proportion = hull_growth.crown_proportion(get_preset("sc_broad_oak"))
    assert proportion == pytest.approx((6.0 + 18.0) / 38.0)
    hull = guessed.maps["hull"]
    assert any("the tree is cut at" in w and "sc_broad_oak's height for its crown's width" in w
               for w in guessed.warnings)
    assert hull.top() - hull.origin[2] == pytest.approx(proportion * hull_growth.crown_width(hull),
                                                        abs=2 * hull.voxel_size)


def test_ground_plane_and_camera_up_on_known_geometry():
    rng = np.random.default_rng(0)
    tilt = np.radians(10.0)
    up = np.array([0.0, np.sin(tilt), np.cos(tilt)])
    u, v = np.array([1.0, 0.0, 0.0]), np.cross(up, [1.0, 0.0, 0.0])
    floor = rng.uniform(-5, 5, (400, 1)) * u + rng.uniform(-5, 5, (400, 1)) * v + 2.0 * up
    tree = rng.uniform(-0.5, 0.5, (200, 3)) + 4.0 * up
    normal, offset, inliers = ground_plane(np.concatenate([floor, tree]), np.array([0.0, 0.0, 1.0]), 0.05, rng)
    assert normal @ up > np.cos(np.radians(0.5)) and abs(offset - 2.0) < 0.01
    assert inliers[:400].all() and not inliers[400:].any()
    assert ground_plane(tree, np.array([0.0, 0.0, 1.0]), 0.01, rng) is None   # no plane holds 10 % of a blob


def test_camera_up_is_the_renders_up(photos):
    # the renders look 8 to 15 degrees down: their mean image-up leans 10 degrees off +Z, towards the tree, but
    # their image-right directions are level and span the level plane over the 90 degree arc
    rotations = np.array([camera.world_to_camera[:3, :3] for camera in photos.cameras])
    sfm = SfmPoints(np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros(0, int), [], 10, "known", 0.0,
                    np.zeros((10, 3)), rotations, np.full(10, 0.5), {})
    mean_up = -rotations[:, 1, :].sum(axis=0)
    assert mean_up[2] / np.linalg.norm(mean_up) < np.cos(np.radians(8.0))
    assert camera_up(sfm)[2] > np.cos(np.radians(1.0))
    # photos that all face one way span one level direction: up is their image-up, 10 degrees down as taken
    alike = dataclasses.replace(sfm, camera_rotations=np.repeat(rotations[:1], 10, axis=0))
    assert camera_up(alike) == pytest.approx(-rotations[0, 1, :])
    with pytest.raises(PhotoError, match="up directions cancel out"):
        camera_up(SfmPoints(sfm.points, sfm.colours, sfm.track_length, [], 2, "known", 0.0, np.zeros((2, 3)),
                            np.array([np.eye(3), np.diag([1.0, -1.0, -1.0])]), np.full(2, 0.5), {}))


def test_cli_refuses_a_bad_camera_height_before_sfm(bare_photos, tmp_path):
    refused = tmp_path / "unscaled.glb"
    bad = subprocess.run(FARM + [str(bare_photos), "--method", "photos", "--out", str(refused), "--camera-height",
                                 "-1"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    lines = [line for line in bad.stderr.splitlines() if line.strip()]
    assert bad.returncode == 2 and len(lines) == 1 and "camera height -1.0 is invalid" in lines[0], bad.stderr
    assert not refused.exists()
    wrong = subprocess.run(FARM + [str(bare_photos), "--method", "cloud", "--out", str(refused)], cwd=tmp_path,
                           capture_output=True, text=True, timeout=300)
    assert wrong.returncode == 2 and "a folder of photos" in wrong.stderr


def test_cli_keeps_colmaps_log_out_of_the_terminal_and_names_its_file(photos, tmp_path):
    out = tmp_path / "tree.glb"
    done = subprocess.run(FARM + [str(photos.cameras_json.parent), "--out", str(out), "--no-complete"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert [line for line in done.stderr.splitlines() if not line.startswith("warning: ")] == [], done.stderr[-3000:]
    log = tmp_path / "tree.sfm.log"
    assert done.stdout.count("\n") == 1 and f"; log {log}; outlines {tmp_path / 'tree.outlines.png'}: a median " \
        in done.stdout, done.stdout
    assert "Feature extraction" in log.read_text()  # COLMAP's own log, whole, in the file
    # the registered cameras beside the GLB, in its frame (the trunk's base at the origin): the photos' own poses
    # moved by the base's place, which the GLB's extras give
    written = json.loads((tmp_path / "tree.cameras.json").read_text())
    base = np.array(next(node for node in read_glb_json(out.read_bytes())["nodes"]
                         if "extras" in node)["extras"]["treefarm"]["base_in_scan_m"])
    given = {view["image"]: Camera.from_dict(view) for view in json.loads(photos.cameras_json.read_text())["views"]}
    assert written["convention"] == "opencv" and len(written["views"]) == len(given)
    for view in written["views"]:
        camera = Camera.from_dict(view)
        assert np.allclose(camera.K, given[view["image"]].K, atol=1e-6)
        assert np.allclose(camera.position + base, given[view["image"]].position, atol=1e-6)
    sheet = Image.open(tmp_path / "tree.outlines.png")
    assert sheet.size[0] > 3 * OUTLINE_SIDE


def test_progress_is_told_each_stage_in_order(photos):
    told = []
    from_photos(photos.cameras_json.parent, settings=SfmSettings(threads=1), completion=False,
                progress=lambda stage, done, total: told.append((stage, done, total)))
    stages = list(dict.fromkeys(stage for stage, _, _ in told))
    assert stages == ["features", "matching", "triangulation", "tree"]
    for stage in stages:
        counts = [(done, total) for name, done, total in told if name == stage]
        assert counts[0][0] == 0 and counts[-1][0] == counts[-1][1] > 0  # each from none to all


def test_bad_arguments_are_one_line(photos, tmp_path):
    folder = photos.cameras_json.parent
    with pytest.raises(PhotoError, match="frame 'world' is not known"):
        from_photos(folder, frame="world")
    with pytest.raises(PhotoError, match=r"height -2 is invalid: allowed a number of metres > 0"):
        from_photos(folder, height=-2)
    with pytest.raises(PhotoError, match="is not a folder"):
        from_photos(tmp_path / "missing", height=3.0)


def test_cli_batch_of_photo_folders_reports_the_blank_one_and_finishes_the_others(photos, bare_photos, tmp_path):
    shoots = tmp_path / "shoots"
    (shoots / "blank").mkdir(parents=True)
    for k in range(4):
        Image.fromarray(np.full((64, 64, 3), 128, np.uint8)).save(shoots / "blank" / f"grey_{k}.png")
    (shoots / "renders").symlink_to(photos.cameras_json.parent, target_is_directory=True)
    (shoots / "phone").symlink_to(bare_photos, target_is_directory=True)
    out = tmp_path / "trees"
    done = subprocess.run(FARM + [str(shoots), "--out", str(out), "--height", "4.3", "--workers", "2",
                                  "--no-complete"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 2, done.stderr[-3000:]
    rows = {Path(r["input"]).name: r for r in csv.DictReader(open(out / "summary.csv"))}
    for name in ("renders", "phone"):
        assert rows[name]["status"] == "ok", rows[name]
        assert_valid_glb((out / f"{name}.glb").read_bytes(), tmp_path)
        assert (out / f"{name}.skeleton.ply").is_file() and (out / f"{name}.branches.csv").is_file()
    # both scaled to the height the command gave (cameras.json's metres give way, with a warning if far off)
    # (the skeleton ends under the sparse top points, short of the given height)
    assert float(rows["phone"]["height_m"]) == pytest.approx(4.3, rel=0.2)
    assert rows["blank"]["status"] == "failed" and "0 of 4 photos have 15 features" in rows["blank"]["message"]
    assert not (out / "blank.glb").exists() and (out / "contact_sheet.png").is_file()


@pytest.fixture(scope="module")
def grown(photos):
    return from_photos(photos.cameras_json.parent, settings=SfmSettings(threads=1), shape="hull")


def test_the_hull_crown_holds_the_tree_and_the_growth_stays_in_it(photos, photo_tree, grown):
    true, mesh = photo_tree
    hull = grown.maps["hull"]                    # known poses: the upright frame is the renders' world
    bark = mesh.bark.vertices.astype(np.float64)[::20]
    assert hull.space().contains(bark).mean() >= 0.8
    shift = -grown.scan.transform[:3, 3]
    nodes = grown.skeleton.positions.astype(np.float64)
    guide = len(grown.maps["main_skeleton"])
    assert hull.space(shift).contains(nodes[guide:]).mean() >= 0.95    # what grew, grew inside the hull
    assert abs(grown.skeleton.height - true.height) <= 0.2 * true.height
    assert len(grown.maps["masks"]) == len(photos.images) and all(m.any() for m in grown.maps["masks"])
    assert {"hull.masks", "hull.hull", "hull.growth"} <= set(grown.timings)
    # The QSM measures (the command's summary, --qsm-csv) are the grown tree's, not the sparse points' skeleton's.
    measures = grown.scan.measures
    assert measures["height_m"] == pytest.approx(float(nodes[:, 2].max() - nodes[0, 2]))
    assert measures["branch_count"] == grown.skeleton.n_branches - 1  # the trunk not counted
    assert measures["scan_height_m"] is not None and measures["trunk_radius_fit_m"] > 0


def _breast_height_radius(skeleton) -> float:
    trunk = np.flatnonzero(skeleton.order == 0)
    above = skeleton.positions[trunk, 2] - skeleton.positions[0, 2]
    return float(np.interp(BREAST_HEIGHT_M, above, skeleton.radius[trunk]))


def test_the_trunk_stands_where_the_masks_put_it_and_is_as_thick_at_breast_height(photos, photo_tree, grown):
    true, _ = photo_tree
    truth = _breast_height_radius(true)                       # 0.11 m
    views = [PinholeView.from_camera(camera) for camera in photos.cameras]
    exact = [np.asarray(Image.open(mask)) > 0 for mask in photos.masks]
    foot = trunk_foot(exact, views, 0.0)
    assert np.linalg.norm(foot[:2] - true.positions[0, :2]) <= 0.15 and foot[2] == 0.0
    assert trunk_radius_from_masks(exact, views, foot) == pytest.approx(truth, rel=0.1)
    # from the photos alone (network masks): the sparse points' stem fit says 0.47 m, their cloud root lies 2 m off;
    # the grown tree stands on the masks' foot, its base frame's origin (0.33 m off: ten photos over 90 degrees)
    assert grown.scan.measures["trunk_radius_fit_m"] == pytest.approx(truth, rel=0.2)
    assert np.linalg.norm(grown.scan.transform[:2, 3] - true.positions[0, :2]) <= 0.1 * true.height
    assert abs(grown.scan.transform[2, 3] - true.positions[0, 2]) <= 0.05
    empty = [np.zeros_like(mask) for mask in exact]
    assert trunk_foot(empty, views, 0.0) is None and trunk_radius_from_masks(empty, views, foot) is None
    # a foot the photos do not see (behind every camera) gives no radius
    assert trunk_radius_from_masks(exact, views, np.array([0.0, 0.0, 1e4])) is None


def test_the_crown_base_from_the_masks_clears_the_hull_under_the_crown(photos, photo_tree, grown):
    true, _ = photo_tree
    views = [PinholeView.from_camera(camera) for camera in photos.cameras]
    exact = [np.asarray(Image.open(mask)) > 0 for mask in photos.masks]
    foot = trunk_foot(exact, views, 0.0)
    # the rays through each mask's trunk bottom meet at the trunk's foot, on the ground (z = 0)
    assert np.linalg.norm(triangulated_foot(exact, views) - true.positions[0]) < 0.15
    assert triangulated_foot(exact[:1], views[:1]) is None
    base = crown_base_from_masks(exact, views, foot, trunk_radius_from_masks(exact, views, foot), true.height)
    branches = true.positions[true.order >= 1, 2]
    # under most of the crown: above its lowest branch (1.04 m), below the lowest quarter of its branch nodes
    assert branches.min() - 0.2 <= base <= np.percentile(branches, 25)
    assert crown_base_from_masks([np.zeros_like(m) for m in exact], views, foot, 0.1, true.height) is None
    # the grown tree's hull (from the photos' own masks) holds nothing under its crown base but the trunk
    # (round the foot the masks give, where the tree stands: a tree SfM placed a few tenths of a metre off keeps
    # its trunk there)
    hull = grown.maps["hull"]
    centres = hull.centres()
    low = centres[centres[:, 2] < 0.5]
    foot = grown.scan.transform[:3, 3]
    assert len(low) and np.linalg.norm(low[:, :2] - foot[:2], axis=1).max() <= 0.3


def test_moving_the_base_keeps_the_points_and_the_measured_skeleton_in_place(grown):
    # moving the base frame's origin keeps every point and the measured skeleton where they are in the scan
    scan = grown.scan
    moved = rerooted(scan, scan.transform[:3, 3] + [0.4, -0.2, 0.1])
    assert np.allclose(moved.base_points + moved.transform[:3, 3], scan.base_points + scan.transform[:3, 3])
    assert np.allclose(moved.measured.positions + moved.transform[:3, 3],
                       scan.measured.positions + scan.transform[:3, 3], atol=1e-5)


def test_same_photos_and_seed_give_the_same_tree_on_every_thread_count(photos, grown):
    # SfM on all CPUs (the command's default) against `grown`'s one thread: the same GLB, byte for byte
    again = from_photos(photos.cameras_json.parent, settings=SfmSettings(threads=0), shape="hull")
    assert again.scan.cloud.points.tobytes() == grown.scan.cloud.points.tobytes()
    assert again.glb() == grown.glb()


def test_sfm_run_once_gives_the_same_tree_as_from_photos_running_it(photos, grown):
    # the bench runs SfM once per registration and passes it to every shape and kind of mask
    folder = photos.cameras_json.parent
    sfm = sfm_points(folder, SfmSettings(threads=1))
    again = from_photos(folder, settings=SfmSettings(threads=1), shape="hull", sfm=sfm)
    assert again.glb() == grown.glb()
    assert {k.removeprefix("sfm."): v for k, v in again.timings.items() if k.startswith("sfm.")} == sfm.timings
    # every point's track: the photos that saw it, as many as its track length
    point, photo = sfm.observations.T
    assert np.bincount(point, minlength=len(sfm.points)).tolist() == sfm.track_length.tolist()
    assert photo.min() >= 0 and photo.max() < len(sfm.registered)
    # the sightlines that carve the hull run from those photos' cameras to the ground near the trunk
    tree = level_and_isolate(sfm, None, np.random.default_rng(0), metric=True)
    views = photo_views(sfm, tree.model_to_upright)
    base = np.array([*np.median(tree.points[:, :2], axis=0), tree.ground_z])
    starts, ends = ground_sightlines(sfm, tree, views, base)
    height = tree.points[:, 2].max() - tree.ground_z
    assert len(ends) >= 100 and np.all(ends[:, 2] < tree.ground_z + 0.05 * height)
    assert np.all(np.linalg.norm(ends[:, :2] - base[:2], axis=1) < 0.4 * height)
    assert {tuple(c) for c in starts} <= {tuple(v.centre) for v in views}


def test_a_bad_shape_or_species_is_one_line(photos):
    folder = photos.cameras_json.parent
    with pytest.raises(PhotoError, match="shape 'dense' is not known: allowed sparse, hull"):
        from_photos(folder, shape="dense")
    with pytest.raises(PhotoError, match="species 'sp_oak' is unknown"):
        from_photos(folder, shape="hull", species="sp_oak")


def test_a_hull_too_porous_round_the_bole_still_grows_a_crown_next_to_it():
    # a crown of isolated voxels (every other one along each axis) over a bole: few internodes land in the hull
    voxel = 0.5
    ijk = np.indices((24, 24, 24)).reshape(3, -1).T
    centre = np.array([12, 12, 14])
    lattice = ijk[(np.linalg.norm(ijk - centre, axis=1) < 8) & np.all(ijk % 2 == 0, axis=1)]
    occupancy = np.zeros((24, 24, 24), bool)
    occupancy[tuple(lattice.T)] = True
    space = VoxelSpace(occupancy, [-6.0, -6.0, 0.0], voxel)
    params = validate(get_preset(DEFAULT_SPECIES).sample(np.random.default_rng(0)))
    bole = Skeleton(np.array([[0, 0, z] for z in np.arange(0.0, 5.5, 0.5)], np.float32), np.arange(-1, 10),
                    np.full(11, 0.05, np.float32), np.zeros(11, np.uint8))      # up into the crown
    alone = grow_in_space(params, np.random.default_rng(1), space=space, internode_length=voxel, guide=bole,
                          guide_buds="all")
    assert len(alone) < 2 * len(bole)                                   # starved in the hull alone
    grown = grow_in_hull_space(params, np.random.default_rng(1), occupancy, space, bole, voxel)
    assert len(grown) >= 5 * len(bole)
    near = VoxelSpace(ndimage.binary_dilation(occupancy, iterations=1), space.origin, voxel)
    assert near.contains(grown.positions[len(bole):].astype(np.float64)).all()   # within a voxel of the hull
