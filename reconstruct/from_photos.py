"""Photos to a tree (issue 24): SfM points (`reconstruct.sfm`), made upright and metric, the tree isolated from
the ground and the clutter, then `from_cloud`.

Upright: known poses (cameras.json) are already Z up in metres. Estimated poses are levelled by the ground plane
(RANSAC over the points, its normal within GROUND_MAX_TILT_DEG of the cameras' mean image-up direction, which
people and our renders keep upright) or, where no plane holds GROUND_MIN_SHARE of the points, by that camera up.
Metric: known poses give metres; estimated ones are scaled so the isolated tree is `height` tall, or, without a
height, so that the cameras stand `camera_height` (CAMERA_HEIGHT_M, a phone held at chest height) above the ground
plane, with a warning; with no ground plane (a ground too plain to match), above the trunk's foot the photos'
masks show (hull shape only); with none of these the scale is unknown and `from_photos` says so.

Isolation, in order: near-black and near-white points (sky, shadow, overexposed bark: colours SfM places badly)
are dropped; the ground plane's band is removed; so is what lies outside the photos' footprint round the point
they aim at (`in_footprint`); the points are linked within LINK_FACTOR times their median
spacing and the largest group kept with the groups inside its footprint (crown fragments the sparse cloud leaves
apart); statistical outliers go next (`skeleton.statistical_inliers`), and last, once in metres, the points near
the ground that are not the trunk's group (from_cloud's one-tree rule would refuse them as a second stem). scipy
does these: open3d, the library that has them, is a 400 MB wheel for a few short steps.

The "scan" frame of a photo tree is the upright metric frame: the cameras' world for known or aligned poses, the
SfM model levelled and scaled about its origin for estimated ones.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from species.timing import StageTimer

from .clouds import MIN_POINTS, read_cloud
from .from_cloud import FRAMES, from_cloud, stem_groups
from .hull_growth import (DEFAULT_SPECIES, aimed_hull, colonization_preset, crown_proportion, crown_width,
                          draw_masks, grow_in_hull, hull_bounds, photo_views, top_unseen, triangulated_foot)
from .photo_folder import CAMERA_HEIGHT_M
from .photo_masks import mask_network
from .result import Reconstruction
from .sfm import PhotoError, Progress, SfmPoints, no_progress, SfmSettings, align_to_cameras, known_cameras, photo_names, sfm_points
from .skeleton import _adjacency, statistical_inliers

__all__ = ["from_photos", "SHAPES", "level_and_isolate", "check_height", "ground_plane", "camera_up", "look_at",
           "in_footprint", "IsolatedTree"]

DARK = 25                 # every channel at or below: near-black (deep shadow, a dark background)
LIGHT = 235               # every channel at or above: near-white (sky, overexposed highlights)
GROUND_MAX_TILT_DEG = 30.0
LEVEL_RIDGE = 0.01        # `camera_up`: image-right spread below this is not taken for a level direction
GROUND_MIN_SHARE = 0.10   # a plane holding fewer of the points is not taken for the ground
GROUND_BAND = 0.006       # the ground band's half-width, a share of the cameras' mean distance to the points
GROUND_TRIALS = 256
LINK_FACTOR = 4.0         # points within this many median spacings are one group
FOOTPRINT_MARGIN = 1.2    # groups whose centre lies within this times the main group's reach are kept
FOOTPRINT_SHARE = 1.0     # of the photos' footprint radius (`in_footprint`)
SHAPES = ("sparse", "hull")  # the crown from the SfM points alone, or grown in the photos' visual hull
HEIGHT_MISMATCH = 0.10    # a given height this far from the known poses' scale is warned about
HULL_RESCALE = 0.02       # a hull this far from the given height scales the tree again, to the hull's height
FOOT_PASSES = 5           # masks redrawn on the trunk's foot they show, where SfM gave no ground plane ...
FOOT_SETTLED = 0.01       # ... until the foot moves less than this share of the tree's points' height


@dataclasses.dataclass(frozen=True, eq=False)
class IsolatedTree:
    """The tree's points in the upright metric frame (Z up; the cameras' world for known or aligned poses, else the
    model levelled, its ground under the tree at z = 0 and scaled to the given height), their colours, where up and
    scale came from, the ground's height under the tree, up (3,) in the SfM model's frame, and the points left
    after each step (`counts`), and model_to_upright (4, 4) the similarity taking the SfM model's frame to the
    upright metric one."""

    points: np.ndarray
    colours: np.ndarray
    up_source: str
    scale_source: str
    scale: float
    ground_z: float
    up: np.ndarray
    counts: dict[str, int]
    model_to_upright: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(4))


def check_height(height, what: str = "height") -> None:
    """PhotoError unless `height` is None or a finite number of metres > 0 (`what` names it in the error)."""
    if height is not None and not (isinstance(height, (int, float, np.number)) and not isinstance(height, bool)
                                   and np.isfinite(height) and height > 0):
        raise PhotoError(f"{what} {height!r} is invalid: allowed a number of metres > 0")


def camera_up(sfm: SfmPoints) -> np.ndarray:
    """(3,) up in the model's frame: the cameras' mean image-up direction (OpenCV: -y in the camera is up), less
    its share along the level directions their image-right directions span. Photos taken upright keep their
    image-right level however far they look up or down, while their image-up leans with the pitch: 8-15 degrees
    down on a 90 degree arc leaned the mean 10 degrees towards the tree, and without a ground plane that lean made
    the tree 70 % too tall. A ridge (LEVEL_RIDGE) leaves the mean as it is along what the right directions do not
    span (photos that all face one way)."""
    ups = -sfm.camera_rotations[:, 1, :]     # R.T @ (0, -1, 0) for each world-to-camera rotation R
    mean = ups.sum(axis=0)
    norm = np.linalg.norm(mean)
    if norm < 1e-9:
        raise PhotoError("the cameras' up directions cancel out: allowed photos taken upright (or cameras.json)")
    rights = sfm.camera_rotations[:, 0, :]   # R.T @ (1, 0, 0)
    spread = rights.T @ rights / len(rights)
    up = np.linalg.solve(spread + LEVEL_RIDGE * np.eye(3), mean / norm)
    return up / np.linalg.norm(up)


def ground_plane(points: np.ndarray, up: np.ndarray, band: float, rng: np.random.Generator
                 ) -> tuple[np.ndarray, float, np.ndarray] | None:
    """RANSAC: the plane (unit normal towards `up`, offset d: n . x = d) holding the most points within `band`,
    its normal within GROUND_MAX_TILT_DEG of `up`, refined by least squares on its inliers; with its inlier mask.
    None when no such plane holds GROUND_MIN_SHARE of the points."""
    if len(points) < 3:
        return None
    trials = rng.integers(0, len(points), size=(GROUND_TRIALS, 3))
    a, b, c = points[trials[:, 0]], points[trials[:, 1]], points[trials[:, 2]]
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    ok = lengths > 1e-12
    normals[ok] /= lengths[ok, None]
    normals *= np.sign(normals @ up)[:, None]
    ok &= normals @ up >= np.cos(np.radians(GROUND_MAX_TILT_DEG))
    if not ok.any():
        return None
    normals, offsets = normals[ok], np.einsum("ij,ij->i", normals[ok], a[ok])
    votes = (np.abs(points @ normals.T - offsets) <= band).sum(axis=0)
    best = int(np.argmax(votes))
    if votes[best] < GROUND_MIN_SHARE * len(points):
        return None
    inliers = np.abs(points @ normals[best] - offsets[best]) <= band
    centre = points[inliers].mean(axis=0)
    normal = np.linalg.svd(points[inliers] - centre, full_matrices=False)[2][-1]
    normal *= np.sign(normal @ up)
    if normal @ up < np.cos(np.radians(GROUND_MAX_TILT_DEG)):
        normal = normals[best]
    offset = float(normal @ centre)
    return normal, offset, np.abs(points @ normal - offset) <= band


def look_at(sfm: SfmPoints) -> np.ndarray:
    """(3,) the point nearest every photo's optical axis (least squares): where the photographer aimed."""
    axes = sfm.camera_rotations[:, 2, :]             # the optical axis in the model's frame, per photo
    projectors = np.eye(3) - axes[:, :, None] * axes[:, None, :]
    try:
        return np.linalg.solve(projectors.sum(axis=0), np.einsum("kij,kj->i", projectors, sfm.camera_centres))
    except np.linalg.LinAlgError:
        raise PhotoError("the photos all look the same way from one line: allowed photos from around the "
                         "tree") from None


def in_footprint(sfm: SfmPoints, points: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(N,) bool: points within the photos' footprint, a vertical cylinder round the aim point whose radius is the
    median over photos of distance x half-width / focal length (a photo that frames the tree whole sees no more
    of it to either side). SfM's false matches on foliage and the background land all round the tree."""
    aim = look_at(sfm)
    flat = lambda v: v - np.outer(v @ up, up)  # noqa: E731  (the part across `up`)
    reach = float(np.median(np.linalg.norm(flat(sfm.camera_centres - aim), axis=1) * sfm.half_widths))
    return np.linalg.norm(flat(points - aim), axis=1) <= FOOTPRINT_SHARE * reach


def _rotation_to_z(up: np.ndarray) -> np.ndarray:
    """The (3, 3) rotation taking unit `up` to +Z by the shortest turn."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s, c = np.linalg.norm(axis), float(up @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K


def _tree_group(points: np.ndarray) -> np.ndarray:
    """(N,) bool: the largest group of points linked within LINK_FACTOR median spacings, with the groups whose
    horizontal centre lies inside its footprint."""
    tree = cKDTree(points)
    spacing = float(np.median(tree.query(points, k=2)[0][:, 1]))
    pairs = tree.query_pairs(max(LINK_FACTOR * spacing, 1e-9), output_type="ndarray")
    count, label = connected_components(_adjacency(pairs, len(points)), directed=False)
    main = int(np.argmax(np.bincount(label, minlength=count)))
    centre = points[label == main, :2].mean(axis=0)
    reach = float(np.linalg.norm(points[label == main, :2] - centre, axis=1).max())
    sums = np.zeros((count, 2))
    np.add.at(sums, label, points[:, :2])
    centres = sums / np.bincount(label, minlength=count)[:, None]
    inside = np.linalg.norm(centres - centre, axis=1) <= FOOTPRINT_MARGIN * reach
    return inside[label]


def level_and_isolate(sfm: SfmPoints, height: float | None, rng: np.random.Generator,
                      metric: bool, camera_height: float = CAMERA_HEIGHT_M, few: bool = False) -> IsolatedTree:
    """The tree's points from SfM's (see the module docstring). metric : the model is already upright in metres
    (known or aligned poses). height : metres, scales the tree to it (over the known scale too, with a warning
    left to the caller). camera_height : metres, the cameras' median height above the ground plane, which scales
    an estimated model given no height (scale_source "camera height"). PhotoError when the scale is unknown or too
    little of the tree is left, unless `few`: then the points left on the tree are kept however few (the photos'
    visual hull can still carve it, `from_photos`), the ground is read under where the photos aim, and a given
    height scales the model as the cameras' height would (scale_source "height": the caller scales the tree to
    its hull's height); with no ground plane either, the cameras' height is taken over the lowest point for now
    (from_photos stands the tree on the trunk's foot the photos' masks show, and scales it again over that)."""
    check_height(height)
    check_height(camera_height, "camera height")
    counts = {"sfm": len(sfm.points)}
    dark = (sfm.colours <= DARK).all(axis=1)
    light = (sfm.colours >= LIGHT).all(axis=1)
    keep = ~(dark | light)
    points, colours = sfm.points[keep], sfm.colours[keep]
    counts["colour"] = len(points)
    if len(points) < MIN_POINTS:
        raise PhotoError(f"SfM placed {counts['sfm']} points, {len(points)} not near-black or near-white: allowed at "
                         f"least {MIN_POINTS}; take more photos, larger, closer to the tree")
    centroid = points.mean(axis=0)
    reach = float(np.linalg.norm(sfm.camera_centres - centroid, axis=1).mean())
    up = np.array([0.0, 0.0, 1.0]) if metric else camera_up(sfm)
    plane = ground_plane(points, up, GROUND_BAND * reach, rng)
    if plane is not None:
        normal, offset, ground = plane
        up_source = "cameras.json and ground plane" if metric else "ground plane"
    else:
        normal, offset = up, None
        ground = np.zeros(len(points), bool)
        up_source = "cameras.json" if metric else "camera up"
    if not metric:
        up = normal
    rotation = np.eye(3) if metric else _rotation_to_z(up)
    upright = points @ rotation.T
    above = ~ground
    if plane is not None:
        # points under the ground are reflections and mismatches
        above &= (points @ normal - offset) > 0
    points, colours, upright = points[above], colours[above], upright[above]
    counts["ground"] = len(points)
    near = in_footprint(sfm, points, up)
    points, colours, upright = points[near], colours[near], upright[near]
    counts["footprint"] = len(points)
    if len(points) < MIN_POINTS and few:
        upright, colours = upright[:0], colours[:0]     # a few points on the ground's edge are not a tree
        counts["cluster"] = counts["outliers"] = 0
    elif len(points) < MIN_POINTS:
        raise PhotoError(f"{counts['colour'] - len(points)} of {counts['colour']} SfM points lie on the ground or "
                         f"outside the photos' footprint: allowed at least {MIN_POINTS} on the tree; take photos "
                         f"that frame the tree larger")
    else:
        group = _tree_group(upright)
        upright, colours = upright[group], colours[group]
        counts["cluster"] = len(upright)
        inliers = statistical_inliers(upright)
        upright, colours = upright[inliers], colours[inliers]
        counts["outliers"] = len(upright)
    if len(upright) < MIN_POINTS and not few:
        raise PhotoError(f"SfM left {len(upright)} points on the tree (of {counts['sfm']}): allowed at least "
                         f"{MIN_POINTS}; take more photos, larger, closer to the tree")
    sparse = len(upright) < MIN_POINTS
    centre = (rotation @ look_at(sfm)) if sparse else upright.mean(axis=0)
    if plane is not None:
        # the plane in the upright frame, at the tree's centre (R n is +Z when levelled by it)
        turned = rotation @ normal
        ground_z = float((offset - turned[:2] @ centre[:2]) / turned[2])
    elif not sparse:
        ground_z = float(upright[:, 2].min())
    else:
        raise PhotoError(f"SfM left {len(upright)} points on the tree (of {counts['sfm']}) and found no ground plane "
                         f"to stand it on: allowed at least {MIN_POINTS} points on the tree, or photos that show "
                         f"the ground round it")
    scale, scale_source = 1.0, "cameras.json" if metric else "none"
    model_to_upright = np.eye(4)
    model_to_upright[:3, :3] = rotation
    if plane is not None:
        above_ground = float(np.median(sfm.camera_centres @ normal - offset))
    elif few and not sparse:
        # for now over the lowest point: from_photos stands the tree on the trunk's foot the masks show, and scales
        # it again by the cameras' height above that (`grounded`)
        above_ground = float(np.median((sfm.camera_centres @ rotation.T)[:, 2])) - ground_z
    else:
        above_ground = 0.0
    if height is not None and not sparse:
        scale, scale_source = float(height) / float(upright[:, 2].max() - ground_z), "height"
    elif height is not None:
        # too few points to measure the tree by: the cameras' height for now, the hull's height later
        scale = float(camera_height) / above_ground if not metric and above_ground > 0 else 1.0
        scale_source = "height"
    elif not metric and above_ground > 0:
        # no height given: the photographer's hand is the only length left (the cameras' height above the ground)
        scale, scale_source = float(camera_height) / above_ground, "camera height"
    elif not metric:
        raise PhotoError("the photos' scale is unknown (no cameras.json, and no ground plane under the cameras to "
                         "stand them on): allowed a tree height in metres (--height M, or height= in Python)")
    if scale_source in ("height", "camera height"):
        # scaled about the ground under the tree, which goes to z = 0
        upright = (upright - np.array([0.0, 0.0, ground_z])) * scale
        model_to_upright[:3] *= scale
        model_to_upright[2, 3] = -scale * ground_z
        ground_z = 0.0
    upright, colours = _one_stem(upright, colours, ground_z)
    counts["stem"] = len(upright)
    return IsolatedTree(upright, colours, up_source, scale_source, scale, ground_z, up, counts, model_to_upright)


def _one_stem(points: np.ndarray, colours: np.ndarray, ground_z: float) -> tuple[np.ndarray, np.ndarray]:
    """The points and colours less those near the ground `ground_z` outside its largest group (one stem: from_cloud
    would refuse the others as a second tree)."""
    low, label = stem_groups(points, ground_z)
    if not len(label):
        return points, colours
    keep = np.ones(len(points), bool)
    keep[np.flatnonzero(low)[label != np.argmax(np.bincount(label))]] = False
    return points[keep], colours[keep]


def rescaled(tree: IsolatedTree, factor: float) -> IsolatedTree:
    """`tree` scaled by `factor` about the origin (a tree scaled by its height has its ground at z = 0 there)."""
    to_upright = tree.model_to_upright.copy()
    to_upright[:3] *= factor
    return dataclasses.replace(tree, points=tree.points * factor, ground_z=tree.ground_z * factor,
                               scale=tree.scale * factor, model_to_upright=to_upright)


def grounded(tree: IsolatedTree, factor: float) -> IsolatedTree:
    """`tree` with its ground moved to z = 0, then scaled by `factor` about it."""
    to_ground = np.eye(4)
    to_ground[2, 3] = -tree.ground_z
    moved = dataclasses.replace(tree, points=tree.points - np.array([0.0, 0.0, tree.ground_z]), ground_z=0.0,
                                model_to_upright=to_ground @ tree.model_to_upright)
    return rescaled(moved, factor)


def from_photos(folder: str | Path, *, height: float | None = None, frame: str = "base", completion: bool = True,
                seed: int = 0, settings: SfmSettings | None = None, name: str = "tree",
                workdir: str | Path | None = None, log: str | Path | None = None,
                progress: Progress | None = None, shape: str = "hull", species: str | None = None,
                masks: str = "network", models=None, mask_net=None, sfm: SfmPoints | None = None,
                camera_height: float = CAMERA_HEIGHT_M) -> Reconstruction:
    """A tree from a folder of photos: `sfm_points`, `level_and_isolate`, then `from_cloud`; its `Reconstruction`
    (method "photos"; timings "sfm.STAGE" per SfM stage, "isolate", then from_cloud's).

    height   : the tree's height in metres; where the folder has no cameras.json and no height is given, the
               cameras are taken to stand `camera_height` metres above the ground plane (with a warning).
    settings : pycolmap's (`SfmSettings`); poses "estimate" with a cameras.json aligns the estimated model onto it.
    frame, completion, seed, name : as `from_cloud`. workdir : keeps COLMAP's database and model there.
    log, progress : where COLMAP's log goes, and who is told each stage's progress (`sfm_points`); after SfM's
               stages comes "tree": the isolation, then the skeleton and the mesh.
    shape    : "sparse" (the cloud method's tree from the SfM points) or "hull": that tree's trunk and main
               branches, then growth of the `species` colonization preset inside the visual hull of the photos'
               tree masks (`reconstruct.hull_growth`; timings "hull.STAGE", maps "hull", "masks", "main_skeleton").
    masks    : how the hull's tree masks are drawn (`reconstruct.photo_masks.MASKS`): "network" (the tree mask
               network: `mask_net` if given, else `models`' (None: the shipped default)) or "classical".
    sfm      : `sfm_points` already run on this folder with `settings` (a benchmark comparing shapes and masks on
               one registration); None runs it. Its timings stand in the result's "sfm.STAGE".
    The result's extras say method "photos" with the SfM record (photos registered, poses, points per step); its
    maps "cameras" hold each registered photo's name and `PinholeView` in the scan frame (`photo_outlines`).
    Raises PhotoError (one line) for a folder SfM cannot turn into one tree.
    """
    if frame not in FRAMES:
        raise PhotoError(f"frame {frame!r} is not known: allowed {', '.join(FRAMES)}")
    if shape not in SHAPES:
        raise PhotoError(f"shape {shape!r} is not known: allowed {', '.join(SHAPES)}")
    network = None
    if shape == "hull":
        colonization_preset(species)  # said before SfM spends minutes
        network = mask_network(masks, models, mask_net)
    check_height(height)
    check_height(camera_height, "camera height")
    settings = SfmSettings() if settings is None else settings
    cameras = known_cameras(folder, photo_names(folder))
    timer = StageTimer()
    if sfm is None:
        sfm = sfm_points(folder, settings, workdir=workdir, log=log, progress=progress)
    timer.lap("sfm")
    progress = progress or no_progress
    progress("tree", 0, 2)
    warnings: list[str] = []
    residual = None
    if sfm.poses == "estimated":
        # a cameras.json that lists only some photos can still place the registered ones
        posed = cameras if cameras is not None else known_cameras(folder, sfm.registered)
        if posed is not None:
            sfm, residual = align_to_cameras(sfm, posed)
    metric = sfm.poses in ("known", "aligned")
    tree = level_and_isolate(sfm, height, np.random.default_rng(seed), metric, camera_height, few=shape == "hull")
    drawn_masks = None
    if len(tree.points) < MIN_POINTS:
        # too few SfM points on the tree to say where it stands or how large it is (a phone's photos of a tree
        # against the sky): the photos' outlines, carved round where they aim, say both; the hull's surface stands
        # in for its cloud
        aim = tree.model_to_upright[:3, :3] @ look_at(sfm) + tree.model_to_upright[:3, 3]
        hull, drawn_masks = aimed_hull(sfm, tree, folder, aim, network)
        surface = hull.origin + (np.argwhere(hull.occupancy & ~ndimage.binary_erosion(hull.occupancy)) + 0.5) \
            * hull.voxel_size
        tree = dataclasses.replace(tree, points=surface, colours=np.full((len(surface), 3), 128, np.uint8))
        if tree.scale_source == "height":
            tree = rescaled(tree, float(height) / (hull.top() - tree.ground_z))
        warnings.append(f"SfM left {tree.counts['outliers']} points on the tree: its place and size are the photos' "
                        "outlines' (carved round where the photos aim)")
    foot_moved = None
    if shape == "hull" and "ground plane" not in tree.up_source:
        # no ground plane among SfM's points (a ground too plain to match): their lowest point is a false match
        # under the ground (on a phone walk round the oak at known poses, 8.9 m under it); the trunk's foot the
        # masks show stands on the ground
        views = photo_views(sfm, tree.model_to_upright)
        ground, foot = tree.ground_z, None
        for _ in range(FOOT_PASSES):
            # the masks are cut below the ground's row in each photo: redrawn on the foot's ground, they show the
            # trunk's bottom nearer its true foot (a bad ground keeps the crown's shadow in them)
            base = np.array([*np.median(tree.points[:, :2], axis=0), ground])
            foot = triangulated_foot(draw_masks(sfm, views, folder, hull_bounds(tree.points, ground), base,
                                                tree.points, network), views)
            if foot is None:
                break
            moved, ground = abs(float(foot[2]) - ground), float(foot[2])
            if moved <= FOOT_SETTLED * float(np.ptp(tree.points[:, 2])):
                break
        if foot is not None:
            # over the lowest point: that point was a false match; under it: SfM placed nothing on the trunk's foot
            above = tree.points[:, 2] >= ground
            if above.sum() >= MIN_POINTS:
                foot_moved = (ground - tree.ground_z, tree.scale)   # said once the tree's scale is final
                points, colours = _one_stem(tree.points[above], tree.colours[above], ground)
                tree = dataclasses.replace(tree, points=points, colours=colours, ground_z=ground)
        if tree.scale_source == "camera height":
            # the views the foot was read in: the ground's move left the frame as it was
            standing = float(np.median([view.centre[2] for view in views])) - tree.ground_z
            if foot is None or standing <= 0:
                raise PhotoError("the photos' scale is unknown (no cameras.json, no ground plane under the cameras, "
                                 "and no trunk's foot in the photos' masks to stand them over): allowed a tree "
                                 "height in metres (--height M, or height= in Python)")
            tree = grounded(tree, float(camera_height) / standing)
    if tree.scale_source == "camera height":
        warnings.append(f"no height given: the tree is scaled so that the cameras stand {camera_height:g} m above the "
                        f"ground ({tree.points[:, 2].max():.1f} m tall); give --height M for its true scale")
    missed = sfm.n_photos - len(sfm.registered)
    if missed:
        warnings.append(f"{missed} of {sfm.n_photos} photos were not registered")
    timer.lap("isolate")
    progress("tree", 1, 2)
    cloud = dataclasses.replace(read_cloud(tree.points), colours=tree.colours, source=str(folder))
    result = from_cloud(cloud, frame=frame, completion=completion, seed=seed, name=name)
    if shape == "hull":
        def regrown(tree: IsolatedTree, drawn: Reconstruction, ceiling: float | None = None) -> Reconstruction:
            # the masks do not change with the scale or the ceiling: drawn once, their seconds kept
            cloud = dataclasses.replace(read_cloud(tree.points), colours=tree.colours, source=str(folder))
            again = grow_in_hull(from_cloud(cloud, frame=frame, completion=completion, seed=seed, name=name),
                                 sfm, tree, folder, species=species, seed=seed, mask_net=network,
                                 masks=drawn.maps["masks"], ceiling=ceiling)
            return dataclasses.replace(again, timings={**again.timings, "hull.masks": drawn.timings["hull.masks"]})

        result = grow_in_hull(result, sfm, tree, folder, species=species, seed=seed, mask_net=network,
                              masks=drawn_masks)
        if top_unseen(result.maps["hull"]):
            reached = result.maps["hull"].top() - tree.ground_z
            if height is not None and metric:
                if tree.scale_source == "height":
                    # the given height cannot be the hull's, which has no top: the cameras' metres hold, cut there
                    reached /= tree.scale
                    tree = dataclasses.replace(grounded(tree, 1.0 / tree.scale), scale_source="cameras.json")
                ceiling, done = float(height), "the hull is cut at the height given, the cameras' metres kept"
            elif height is None:
                ceiling = crown_proportion(colonization_preset(species)) * crown_width(result.maps["hull"])
                done = (f"the tree is cut at {min(ceiling, reached):.1f} m, {species or DEFAULT_SPECIES}'s height "
                        f"for its crown's width; give --height M")
            else:
                ceiling, done = None, "scaled to the height given by that hull, the tree may be too narrow"
            warnings.append(f"no photo shows the crown's top (its hull fills its box up to {reached:.1f} m): {done}")
            if ceiling is not None and ceiling < reached:
                result = regrown(tree, result, tree.ground_z + ceiling)
        hull_height = result.maps["hull"].top() - tree.ground_z
        factor = float(height) / hull_height if tree.scale_source == "height" else 1.0
        if abs(factor - 1.0) > HULL_RESCALE:
            # the given height is the tree's, and the hull is the tree's outline: the points' top it was first
            # scaled by can be a stray point over the crown (in leaf 30 % too tall)
            tree = rescaled(tree, factor)
            result = regrown(tree, result)
    if foot_moved is not None:
        moved = foot_moved[0] * tree.scale / foot_moved[1]
        warnings.insert(0, f"SfM found no ground plane: the ground is where the photos' masks show the trunk's foot, "
                           f"{abs(moved):.1f} m {'over' if moved > 0 else 'under'} the lowest SfM point")
    if metric and tree.scale_source == "height" and abs(tree.scale - 1.0) > HEIGHT_MISMATCH:
        warnings.append(f"height {height} m scales the tree by {tree.scale:.2f} from the cameras' metres "
                        f"(cameras.json makes it {height / tree.scale:.2f} m tall)")
    progress("tree", 2, 2)
    record = {"photos": sfm.n_photos, "registered": len(sfm.registered), "poses": sfm.poses,
              "reprojection_px": round(sfm.reprojection_px, 4), "up": tree.up_source, "scale": tree.scale_source,
              "scale_factor": tree.scale, "points": tree.counts}
    if residual is not None:
        record["alignment_residual_m"] = round(residual, 4)
    timings = {**{f"sfm.{k}": v for k, v in sfm.timings.items()}, "isolate": timer.seconds["isolate"],
               **result.timings}
    cameras = tuple(zip(sfm.registered, photo_views(sfm, tree.model_to_upright)))
    return dataclasses.replace(result, method="photos", warnings=(*warnings, *result.warnings), timings=timings,
                               maps={**result.maps, "cameras": cameras},
                               scan=dataclasses.replace(result.scan, provenance={"sfm": record}))
