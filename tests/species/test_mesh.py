"""Specification of species.meshing.tubes_and_cards: bark tubes along branches and leaf cards, from a Skeleton."""
import numpy as np
import pytest

from species.errors import ParameterError
from species.meshing.tubes_and_cards import MeshBuildError, build_mesh, radial_segments
from species.skeleton import Skeleton
from fixtures.skeletons import fork_with_leaves, leaf_transforms, random_tree, straight_trunk


@pytest.fixture(scope="module")
def random_skeleton():
    return random_tree(np.random.default_rng(7), n_nodes=1500, n_leaves=3000)


@pytest.fixture(scope="module")
def random_mesh(random_skeleton):
    return build_mesh(random_skeleton)


def _nearest_on_branch(skeleton, mesh):
    """(V, 3) nearest point on each bark vertex's own branch polyline (brute force per branch)."""
    vertices = mesh.bark.vertices.astype(np.float64)
    nearest = np.empty_like(vertices)
    branch = mesh.bark.attributes["branch"]
    for b in np.unique(branch):
        rows = np.flatnonzero(branch == b)
        path = skeleton.positions[skeleton.branch_paths[b]].astype(np.float64)
        start, seg = path[:-1], np.diff(path, axis=0)
        rel = vertices[rows, None, :] - start[None]
        t = np.clip(np.einsum("vsk,sk->vs", rel, seg) / np.maximum((seg ** 2).sum(1), 1e-30), 0, 1)
        points = start[None] + t[..., None] * seg[None]
        best = np.argmin(((vertices[rows, None, :] - points) ** 2).sum(-1), axis=1)
        nearest[rows] = points[np.arange(len(rows)), best]
    return nearest


def _seam_rows(mesh, branch):
    """Vertex indices of the u = 0 column of each ring of `branch`, in ring order."""
    rows = np.flatnonzero((mesh.bark.attributes["branch"] == branch) & (mesh.bark.uvs[:, 0] == 0))
    return rows


def test_mesh_has_finite_values_and_valid_indices(random_mesh):
    for part in (random_mesh.bark, random_mesh.leaves):
        assert np.isfinite(part.vertices).all() and np.isfinite(part.normals).all() and np.isfinite(part.uvs).all()
        assert part.faces.min() >= 0 and part.faces.max() < part.n_vertices


@pytest.mark.parametrize("make", [fork_with_leaves, straight_trunk])
def test_bark_has_no_degenerate_faces(make):
    bark = build_mesh(make()).bark
    faces = bark.faces
    assert np.all((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2]))
    assert bark.face_areas.min() > 1e-8


def test_random_tree_bark_has_no_degenerate_faces(random_mesh):
    assert random_mesh.bark.face_areas.min() > 1e-10


def test_normals_are_unit_length(random_mesh):
    for part in (random_mesh.bark, random_mesh.leaves):
        np.testing.assert_allclose(np.linalg.norm(part.normals, axis=1), 1.0, atol=1e-5)


@pytest.mark.parametrize("which", ["fork", "random"])
def test_bark_normals_point_away_from_the_branch_axis(which, random_skeleton, random_mesh):
    skeleton = fork_with_leaves() if which == "fork" else random_skeleton
    mesh = build_mesh(skeleton) if which == "fork" else random_mesh
    outward = mesh.bark.vertices - _nearest_on_branch(skeleton, mesh)
    off_axis = np.linalg.norm(outward, axis=1) > 1e-6  # all but the trunk's base centre
    assert np.all(np.einsum("ij,ij->i", mesh.bark.normals, outward)[off_axis] > 0)


def test_face_winding_agrees_with_vertex_normals(random_mesh):
    for part in (random_mesh.bark, random_mesh.leaves):
        tri = part.vertices[part.faces].astype(np.float64)
        geometric = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        assert np.all(np.einsum("ij,ij->i", geometric, part.normals[part.faces].sum(axis=1)) > 0)


def test_tube_vertices_lie_at_the_node_radius():
    skeleton = straight_trunk(height=2.0, base_radius=0.1, n_nodes=5)
    bark = build_mesh(skeleton).bark
    distance = np.linalg.norm(bark.vertices[:, :2], axis=1)
    on_ring = distance > 1e-6
    node_of_ring = np.rint(bark.vertices[on_ring, 2] / 0.5).astype(int)  # nodes every 0.5 m
    np.testing.assert_allclose(distance[on_ring], skeleton.radius[node_of_ring], rtol=1e-5)


def test_tree_base_is_at_the_origin(random_mesh):
    bark = random_mesh.bark
    assert abs(float(bark.vertices[:, 2].min())) < 1e-6
    base = np.unique(bark.vertices[bark.vertices[:, 2] < 1e-6], axis=0)  # base ring (seam once) and centre
    np.testing.assert_allclose(base.mean(axis=0), 0.0, atol=1e-6)


def test_tips_are_closed_by_a_cone_beyond_the_last_node():
    bark = build_mesh(straight_trunk(height=2.0)).bark
    top = int(np.argmax(bark.vertices[:, 2]))
    assert bark.vertices[top, 2] > 2.0 and np.linalg.norm(bark.vertices[top, :2]) < 1e-6
    np.testing.assert_allclose(bark.normals[top], [0, 0, 1], atol=1e-6)
    assert np.sum(np.any(bark.faces == top, axis=1)) == 8  # one triangle per side


def test_v_increases_along_every_branch(random_mesh):
    branch = random_mesh.bark.attributes["branch"]
    for b in np.unique(branch):
        v = random_mesh.bark.uvs[_seam_rows(random_mesh, b), 1]
        assert len(v) >= 2 and np.all(np.diff(v) > 0), f"branch {b}"


def test_u_spans_whole_tiles_around_each_ring(random_mesh):
    bark = random_mesh.bark
    for b in np.unique(bark.attributes["branch"])[:50]:
        u = bark.uvs[bark.attributes["branch"] == b, 0]
        assert u.min() == 0 and u.max() >= 1 and float(u.max()).is_integer()


def test_repeated_points_are_merged():
    skeleton = fork_with_leaves()  # trunk nodes 2 and 3 coincide
    mesh = build_mesh(skeleton)
    assert len(_seam_rows(mesh, 0)) == len(skeleton.branch_paths[0]) - 1


def test_a_branch_that_doubles_back_onto_itself_is_merged_not_refused():
    # A stem pruned to almost nothing: 0.1 mm out (merged into the thick point before it) and back to a hair
    # from where it left (far from the merged point, so kept): only a second pass finds the two ends together.
    positions = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2], [1e-4, 0, 2], [0, 0, 2 + 1e-7], [0, 0, 3]])
    radius = np.array([0.05, 0.05, 0.01, 0.01, 1e-4, 1e-4])
    skeleton = Skeleton(positions.astype(np.float32), np.array([-1, 0, 1, 2, 3, 4], np.int32),
                        radius.astype(np.float32), np.zeros(6, np.uint8))
    mesh = build_mesh(skeleton)
    assert mesh.n_faces > 0 and np.isfinite(mesh.bark.vertices).all()
    assert len(_seam_rows(mesh, 0)) == len(skeleton.branch_paths[0]) - 2


def test_child_tubes_start_inside_their_parent():
    skeleton = fork_with_leaves()
    bark = build_mesh(skeleton).bark
    for b, path in enumerate(skeleton.branch_paths[1:], start=1):
        first_ring = _seam_rows(build_mesh(skeleton), b)[0]
        ring = bark.vertices[first_ring:first_ring + 6]  # order-1 and 2 branches have 6 sides
        distance = np.linalg.norm(ring - skeleton.positions[path[0]], axis=1)
        assert np.all(distance <= skeleton.radius[path[0]] + 1e-6)
        # ... and, thinner than the parent, it starts behind the junction along its own direction.
        heading = skeleton.positions[path[1]] - skeleton.positions[path[0]]
        assert np.dot(ring.mean(axis=0) - skeleton.positions[path[0]], heading) < 0


def test_bark_attributes_name_order_and_branch(random_skeleton, random_mesh):
    attrs = random_mesh.bark.attributes
    assert attrs["order"].dtype == np.uint8 and attrs["branch"].dtype == np.int32
    own_node = random_skeleton.branch_starts[attrs["branch"]]
    np.testing.assert_array_equal(attrs["order"], random_skeleton.order[own_node])


def test_one_card_per_leaf(random_skeleton, random_mesh):
    leaves = random_mesh.leaves
    assert leaves.n_faces == 2 * random_skeleton.n_leaves and leaves.n_vertices == 4 * random_skeleton.n_leaves
    assert leaves.attributes["node"].dtype == np.int32
    np.testing.assert_array_equal(leaves.attributes["node"], np.repeat(random_skeleton.leaf_node, 4))
    np.testing.assert_array_equal(leaves.uvs[:4], [[0, 0], [1, 0], [1, 1], [0, 1]])
    np.testing.assert_allclose(leaves.vertices.reshape(-1, 4, 3), random_skeleton.leaf_corners(), atol=1e-6)


def test_leaf_normal_is_the_card_plus_y_axis():
    skeleton = fork_with_leaves()
    normal_axis = skeleton.leaves[:, :3, 1] / np.linalg.norm(skeleton.leaves[:, :3, 1], axis=1, keepdims=True)
    np.testing.assert_allclose(build_mesh(skeleton).leaves.normals[::4], normal_axis, atol=1e-6)


def test_default_sides_follow_order_and_thick_trunks_get_more():
    np.testing.assert_array_equal(radial_segments([0, 1, 2, 3, 6], [0.05] * 5), [8, 6, 6, 4, 4])
    thick = radial_segments([0], [0.4])[0]
    assert 8 < thick <= 16


def test_mesh_radial_segments_parameter_sets_the_sides():
    mesh = build_mesh(straight_trunk(n_nodes=5), {"mesh_radial_segments": [5]})
    assert mesh.bark.n_vertices == 5 * (5 + 1) + 2  # five rings with a seam column, apex, base centre


def test_mesh_min_segments_raises_the_side_count():
    mesh = build_mesh(straight_trunk(n_nodes=5), {"mesh_radial_segments": [4], "mesh_min_segments": 7})
    assert mesh.bark.n_vertices == 5 * (7 + 1) + 2


def leaning_low_tree() -> Skeleton:
    """A 0.3 m trunk leaning 40 degrees from the origin, a junction 0.15 m up whose 0.25 m branch rises, and a
    0.1 m branch drooping to a tip 0.05 m above the ground."""
    lean = np.array([np.sin(np.radians(40.0)), 0.0, np.cos(np.radians(40.0))])
    trunk = lean[None] * np.array([0.0, 0.2, 1.0, 2.0])[:, None]
    positions = np.concatenate([trunk, [[0.3, 0.4, 0.5], [0.6, 0.9, 0.9], [1.0, -0.5, 0.6], [1.6, -1.0, 0.05]]])
    parent = [-1, 0, 1, 2, 1, 4, 2, 6]
    return Skeleton(positions, parent, [0.3, 0.3, 0.25, 0.2, 0.25, 0.2, 0.1, 0.08], [0, 0, 0, 0, 1, 1, 1, 1])


def test_ground_clear_keeps_every_ring_and_tip_above_the_ground():
    tree = leaning_low_tree()
    assert build_mesh(tree).bark.vertices[:, 2].min() < -0.05  # upright rings on that lean dip into the ground
    cleared = build_mesh(tree, {"mesh_ground_clear": True}).bark
    assert cleared.vertices[:, 2].min() >= -1e-6
    # A tree none of whose rings reaches the ground meshes as it did.
    upright = straight_trunk()
    np.testing.assert_array_equal(build_mesh(upright, {"mesh_ground_clear": True}).bark.vertices,
                                  build_mesh(upright).bark.vertices)


def test_colours_come_from_params():
    mesh = build_mesh(straight_trunk(), {"bark_color": [0.5, 0.4, 0.3], "leaf_color": (0.1, 0.6, 0.1)})
    assert mesh.bark_color == (0.5, 0.4, 0.3) and mesh.leaf_color == (0.1, 0.6, 0.1)


@pytest.mark.parametrize("params, key", [
    ({"mesh_radial_segments": [2]}, "mesh_radial_segments"),
    ({"mesh_radial_segments": "8"}, "mesh_radial_segments"),
    ({"mesh_min_segments": 1}, "mesh_min_segments"),
    ({"mesh_ground_clear": "yes"}, "mesh_ground_clear"),
    ({"bark_color": [2, 0, 0]}, "bark_color"),
    ({"leaf_color": [0.1, 0.2]}, "leaf_color"),
])
def test_bad_mesh_parameters_are_rejected(params, key):
    with pytest.raises(ParameterError, match=key):
        build_mesh(straight_trunk(), params)


def test_a_mistyped_mesh_key_is_rejected_naming_the_known_mesh_keys():
    with pytest.raises(ParameterError) as info:
        build_mesh(straight_trunk(), {"mesh_radial_segment": [5]})
    assert info.value.key == "mesh_radial_segment"
    assert "mesh_radial_segments" in str(info.value) and "mesh_min_segments" in str(info.value)


def test_generator_keys_beside_the_mesh_keys_are_ignored():
    growth = {"generator": "weber_penn", "levels": 3, "branches": [0, 50, 30, 10], "meshy": True}
    mesh = build_mesh(straight_trunk(n_nodes=5), {**growth, "mesh_radial_segments": [5]})
    assert mesh.bark.n_vertices == 5 * (5 + 1) + 2


def test_a_flat_leaf_transform_is_rejected():
    trunk = straight_trunk()
    leaves = leaf_transforms(trunk.positions[[4]], [[0, 0, 1]], [[1, 0, 0]], [0.1])
    leaves[0, :3, 0] = 0.0  # zero width
    skeleton = Skeleton(trunk.positions, trunk.parent, trunk.radius, trunk.order, leaves, [4])
    with pytest.raises(MeshBuildError, match="leaf 0"):
        build_mesh(skeleton)


def test_a_root_only_skeleton_gives_empty_bark():
    mesh = build_mesh(Skeleton(np.zeros((1, 3)), [-1], [0.1], [0]))
    assert mesh.bark.n_faces == 0 and mesh.leaves.n_faces == 0


def test_same_skeleton_gives_identical_arrays(random_skeleton, random_mesh):
    again = build_mesh(random_skeleton)
    for a, b in ((random_mesh.bark, again.bark), (random_mesh.leaves, again.leaves)):
        for name in ("vertices", "faces", "normals", "uvs"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_branches_without_tip_cones_lose_exactly_their_cone_faces_and_apex(random_skeleton):
    from species.meshing.tubes_and_cards import bark_part

    n_branches = random_skeleton.n_branches
    sides = np.full(n_branches, 3)
    coned = bark_part(random_skeleton, branch_sides=sides)
    no_cone = np.arange(n_branches) % 2 == 1
    bare = bark_part(random_skeleton, branch_sides=sides, tip_cones=~no_cone)
    meshed = np.unique(coned.attributes["branch"])
    dropped = np.isin(meshed, np.flatnonzero(no_cone)).sum()
    assert coned.n_faces - bare.n_faces == 3 * dropped
    assert coned.n_vertices - bare.n_vertices == dropped


def test_branch_sides_override_the_sides_by_order(random_skeleton):
    from species.meshing.tubes_and_cards import bark_part

    sides = np.where(np.arange(random_skeleton.n_branches) % 3 == 0, 5, 3)
    bark = bark_part(random_skeleton, branch_sides=sides)
    branch = bark.attributes["branch"]
    # every ring has S + 1 vertices (seam duplicated): a branch's vertex count minus its apex is a multiple
    for b in np.unique(branch)[:50]:
        ring_vertices = (branch == b).sum() - 1 - (b == 0)  # apex, and the root's base centre
        assert ring_vertices % (sides[b] + 1) == 0


def test_face_corners_and_centroids_are_the_faces_vertices_in_float64(random_mesh):
    for part in (random_mesh.bark, random_mesh.leaves):
        corners, centroids = part.face_corners, part.face_centroids
        assert corners.shape == (part.n_faces, 3, 3) and corners.dtype == np.float64
        assert np.array_equal(corners, part.vertices[part.faces].astype(np.float64))
        assert np.allclose(centroids, part.vertices[part.faces].mean(axis=1), atol=1e-6)
        assert part.face_corners is corners  # gathered once per part
        with pytest.raises(ValueError):
            corners[0, 0, 0] = 1.0  # shared by every caller: read-only
