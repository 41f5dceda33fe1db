"""The reconstruction tests' shared photos: one orbit of Blender renders for reconstruct.sfm and from_photos."""
from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

import species
from renderers.blender import render_photos
from renderers.camera import perspective_camera
from species.tree_mesh import MeshPart

PHOTO_VIEWS = 10
PHOTO_STEP_DEG = 10.0   # SIFT on a tree needs small steps: at 60 degrees apart almost nothing matches
PHOTO_SIZE = 320


@pytest.fixture(scope="session")
def photo_tree():
    """The 4.3 m fruit tree the photos show: (skeleton, mesh)."""
    return species.rebuild(species.sample("sc_open_fruit_tree", np.random.default_rng(1)))


@pytest.fixture(scope="session")
def photos(photo_tree, tmp_path_factory):
    """Ten 320 px Cycles renders (4 samples) of the tree in winter (no leaves) on a textured ground, 10 degrees
    apart, with cameras.json. In leaf, 14 % of the points SfM places above the ground land on the tree at this size;
    leafless, about 70 % of those near the tree (docs/reconstruct.md)."""
    _, mesh = photo_tree
    mesh = dataclasses.replace(mesh, leaves=MeshPart.empty())
    points = mesh.bark.vertices
    cameras = [perspective_camera(points, k * PHOTO_STEP_DEG, 15.0 if k % 2 else 8.0, PHOTO_SIZE)
               for k in range(PHOTO_VIEWS)]
    return render_photos(mesh.to_glb(), cameras, tmp_path_factory.mktemp("photos"), samples=4)


@pytest.fixture(scope="session")
def bare_photos(photos, tmp_path_factory):
    """The same photos alone, as a camera gives them: no cameras.json, depth or masks."""
    folder = tmp_path_factory.mktemp("bare-photos")
    for image in photos.images:
        shutil.copy(image, folder / image.name)
    return folder
