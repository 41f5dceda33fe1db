"""reconstruct.cloud_sampling: synthetic scans of generated trees (the clouds' ground truth)."""
import numpy as np
import pytest

import species
from reconstruct.cloud_sampling import LEAF, OUTLIER, WOOD, sample_tree_cloud
from reconstruct.clouds import CloudError


@pytest.fixture(scope="module")
def tree():
    return species.rebuild(species.sample("sc_open_fruit_tree", np.random.default_rng(1)))


def test_labels_follow_the_asked_shares_and_wood_lies_on_the_bark(tree):
    skeleton, mesh = tree
    scan = sample_tree_cloud(mesh, np.random.default_rng(0), n_points=5000, leaf_fraction=0.3,
                             outlier_fraction=0.05, noise_m=0.0)
    counts = np.bincount(scan.labels, minlength=3)
    assert counts.tolist() == [3250, 1500, 250]
    # Without noise a wood point lies on a bark triangle: within the tube's radius of the skeleton.
    from reconstruct.metrics import bark_distances

    assert np.median(bark_distances(skeleton, scan.points[scan.labels == WOOD])) < 0.02
    assert (scan.labels[scan.labels != WOOD] >= LEAF).all() and OUTLIER in scan.labels


def test_the_occlusion_wedge_is_empty_and_the_scan_is_seeded(tree):
    _, mesh = tree
    a = sample_tree_cloud(mesh, np.random.default_rng(4), n_points=4000, occlusion_wedge_deg=90.0)
    b = sample_tree_cloud(mesh, np.random.default_rng(4), n_points=4000, occlusion_wedge_deg=90.0)
    assert a.points.tobytes() == b.points.tobytes()
    assert 2600 < len(a.points) < 3600     # about a quarter of the azimuths removed
    centre = mesh.bark.vertices.mean(axis=0)
    azimuth = np.sort(np.degrees(np.arctan2(a.points[:, 1] - centre[1], a.points[:, 0] - centre[0])))
    gaps = np.diff(np.r_[azimuth, azimuth[0] + 360])
    assert gaps.max() > 60.0               # the wedge, seen from the trunk's side, is a wide empty sector


def test_bad_arguments_are_one_line(tree):
    _, mesh = tree
    rng = np.random.default_rng(0)
    with pytest.raises(CloudError, match="n_points"):
        sample_tree_cloud(mesh, rng, n_points=0)
    with pytest.raises(CloudError, match="leaf_fraction \\+ outlier_fraction"):
        sample_tree_cloud(mesh, rng, n_points=10, leaf_fraction=0.6, outlier_fraction=0.5)
    with pytest.raises(CloudError, match="occlusion_wedge_deg"):
        sample_tree_cloud(mesh, rng, n_points=10, occlusion_wedge_deg=400)
