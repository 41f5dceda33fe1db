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
# The photos without cameras.json are larger: with estimated poses, SfM on 320 px renders left 72-99 points on
# the tree on one machine for every seed tried (100 needed), 400 px renders enough for every seed.
BARE_PHOTO_SIZE = 400


@pytest.fixture(scope="session")
def photo_tree():
    """The 4.3 m fruit tree the photos show: (skeleton, mesh)."""
    return species.rebuild(species.sample("sc_open_fruit_tree", np.random.default_rng(1)))


@pytest.fixture(scope="session")
def photos(photo_tree, tmp_path_factory):
    """Ten 320 px Cycles renders (4 samples) of the tree in winter (no leaves) on a textured ground, 10 degrees
    apart, with cameras.json. Leafless, because in leaf few of the points SfM places above the ground land on the
    tree at this size (docs/reconstruct.md gives the shares)."""
    return _orbit(photo_tree, PHOTO_SIZE, tmp_path_factory.mktemp("photos"))


def _orbit(photo_tree, size: int, folder):
    _, mesh = photo_tree
    mesh = dataclasses.replace(mesh, leaves=MeshPart.empty())
    points = mesh.bark.vertices
    cameras = [perspective_camera(points, k * PHOTO_STEP_DEG, 15.0 if k % 2 else 8.0, size)
               for k in range(PHOTO_VIEWS)]
    return render_photos(mesh.to_glb(), cameras, folder, samples=4)


@pytest.fixture(scope="session")
def bare_photos(photo_tree, tmp_path_factory):
    """The same orbit at BARE_PHOTO_SIZE, alone as a camera gives it: no cameras.json, depth or masks."""
    rendered = _orbit(photo_tree, BARE_PHOTO_SIZE, tmp_path_factory.mktemp("bare-renders"))
    folder = tmp_path_factory.mktemp("bare-photos")
    for image in rendered.images:
        shutil.copy(image, folder / image.name)
    return folder
