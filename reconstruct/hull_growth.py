"""A photo tree's crown grown inside its visual hull (issue 51): masks of every registered photo
(`photo_masks`), the hull they carve from the SfM cameras (`visual_hull`), cleared under the crown's base where
the masks show the trunk (`trunk_foot`, `trunk_radius_from_masks`, `crown_base_from_masks`: no photo from above
the ground carves the space under a wide crown) and along the sightlines to the ground SfM saw under the crown
(`ground_sightlines`: they carve what the masks' shadows keep), and self-organizing growth that fills it from a
bole: where the masks show the trunk, straight up from their foot to the crown's base (the tree's base moves to
that foot); else the species preset's, from the cloud method's root.

In: the SfM model (`SfmPoints`, with each photo's intrinsics), the isolated tree (`IsolatedTree`: its points and
the map from the model's frame to the upright metric one), the photos' folder and the cloud method's
`Reconstruction` of those points. Out: that reconstruction with the grown skeleton and mesh in place of the
completed one; its scan keeps the measured skeleton, and its QSM measures are the grown tree's (the sparse
points' skeleton follows leaves and clutter in leaf: its heights and volumes are not the tree's) and the trunk's
radius the masks' (`trunk_radius_from_masks`); the scan's height is still the points'.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage

from species.colonization import VoxelSpace, bole_guide, grow_in_space, validate
from species.meshing import build_mesh
from species.presets import Preset, PresetError, get_preset
from species.skeleton import Skeleton
from species.timing import StageTimer

from .from_sketch import DEFAULT_SPECIES
from ._sketch_arrays import mask_runs
from .photo_masks import MaskNetwork, photo_mask, tree_window
from .photo_folder import PhotoError
from .qsm import BREAST_HEIGHT_M, qsm_measures
from .result import Reconstruction, ScanRecord
from .visual_hull import PinholeView, VisualHull, carve

__all__ = ["grow_in_hull", "colonization_preset", "photo_views", "hull_bounds", "rerooted", "ground_sightlines",
           "draw_masks", "aimed_bounds", "aimed_hull", "triangulated_foot",
           "grow_in_hull_space", "took_hold", "trunk_foot", "trunk_widths", "trunk_radius_from_masks",
           "crown_base_from_masks", "top_unseen", "crown_proportion", "crown_width", "DEFAULT_SPECIES",
           "HULL_VOXELS"]

HULL_VOXELS = 64          # voxels along the hull box's longest side
GROUND_SIGHT_BAND = 0.05  # of the tree's height: SfM points this near the ground plane are the ground's
GROUND_SIGHT_REACH = 0.4  # of the tree's height: ground points this near the trunk's base carve the hull
GROWTH_REACH = 3          # voxels: how far outside a porous hull the growth may be let to place its internodes
HULL_MARGIN = 0.15        # the box round the tree's points grows by this share of its extent on every side
TRUNK_LOW = 0.1          # of a mask's rows: the trunk's vertical run ends this near its lowest tree pixel
# A trunk radius from the masks above this share of the tree's height is the crown's low leaves hiding the trunk
# at breast height (the presets' trunks are under 4 % of their heights)
MAX_TRUNK_SHARE = 0.075
ROOT_AGREE = 0.1          # of the tree's height: the sparse points' root this near the masks' foot stands
CROWN_STEP = 0.1         # m: the heights at which the photos' masks are read up the trunk
CROWN_WIDENS = 3.0        # trunk diameters: the tree across the trunk's axis wider than this is the crown
CROWN_BASE_QUANTILE = 0.75
TRUNK_SEARCH = 0.02       # of a photo's width: how far from the trunk's projected axis its run of mask pixels may start
# A tree SfM left too few points on is carved in a box round where the photos aim, this share of the cameras'
# median horizontal distance to every side (a photographer walking round a tree stays outside its crown)
AIMED_REACH = 0.9
AIMED_MAX_ELEVATION_DEG = 75.0   # a photo's top edge steeper than this bounds nothing


def photo_views(sfm, model_to_upright: np.ndarray) -> list[PinholeView]:
    """Each registered photo's camera in the upright metric frame (`SfmPoints` with intrinsics and sizes)."""
    if sfm.intrinsics is None or sfm.sizes is None:
        raise PhotoError("the SfM model carries no camera intrinsics: allowed one from `sfm_points`")
    linear, shift = model_to_upright[:3, :3], model_to_upright[:3, 3]
    scale = float(np.cbrt(np.linalg.det(linear)))
    rotation = linear / scale
    views = []
    for R, centre, K, size in zip(sfm.camera_rotations, sfm.camera_centres, sfm.intrinsics, sfm.sizes):
        views.append(PinholeView(R @ rotation.T, linear @ centre + shift, (float(K[0, 0]), float(K[1, 1])),
                                 (float(K[0, 2]), float(K[1, 2])), (int(size[0]), int(size[1]))))
    return views


def _trunk_pixel(mask: np.ndarray) -> tuple[float, float] | None:
    """(u, v) the bottom of the trunk in one tree mask: the foot of the longest vertical run of tree pixels among
    the runs that reach the mask's lowest TRUNK_LOW share of rows (the trunk stands on the ground and runs up
    into the crown; the ground's false spots are short)."""
    rows = np.flatnonzero(mask.any(axis=1))
    if len(rows) == 0:
        return None
    columns, top, length, _ = mask_runs(mask.T)
    bottom = top + length - 1
    reach = np.flatnonzero(bottom >= rows[-1] - TRUNK_LOW * (rows[-1] - rows[0]))
    best = reach[np.argmax(length[reach])]
    return columns[best] + 0.5, bottom[best] + 0.5


def trunk_foot(masks: list[np.ndarray], views: list[PinholeView], ground_z: float) -> np.ndarray | None:
    """(3,) the trunk's foot on the ground plane z = `ground_z`: in each photo the bottom of the trunk in its mask
    (`_trunk_pixel`) cast onto that plane along its ray; the median over the photos. None when no photo gives
    one. The cloud's own root can lie metres off in sparse SfM points."""
    feet = []
    for mask, view in zip(masks, views):
        pixel = _trunk_pixel(mask)
        if pixel is None:
            continue
        ray = view.rotation.T @ np.array([(pixel[0] - view.principal[0]) / view.focal[0],
                                          (pixel[1] - view.principal[1]) / view.focal[1], 1.0])
        if ray[2] >= -1e-9:
            continue                                   # at or above the horizon: the ray misses the ground
        feet.append(view.centre + (ground_z - view.centre[2]) / ray[2] * ray)
    if not feet:
        return None
    foot = np.median(np.asarray(feet), axis=0)
    return np.array([foot[0], foot[1], ground_z])


def trunk_widths(mask: np.ndarray, view: PinholeView, foot: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """(K,) metres: the width of the tree in one photo's mask across the trunk's axis at each of `heights` (K,)
    above `foot` (3,): the run of tree pixels on the axis's row at (or within TRUNK_SEARCH of) the axis, in
    metres at the axis's depth. 0 where the row has no such run, NaN where the axis is out of the photo or the
    run reaches the photo's side (not whole)."""
    points = np.asarray(foot, np.float64) + np.outer(heights, [0.0, 0.0, 1.0])
    uv, depth = view.project(points)
    height, width = mask.shape
    rows = np.floor(uv[:, 1]).astype(np.int64)
    seen = np.flatnonzero((depth > 0) & (rows >= 0) & (rows < height) & (uv[:, 0] >= 0) & (uv[:, 0] < width))
    out = np.full(len(heights), np.nan)
    out[seen] = 0.0
    line, first, length, _ = mask_runs(mask[rows[seen]])     # line k: the row of heights[seen[k]]
    stop = first + length
    u = uv[seen[line], 0]
    gap = np.maximum(np.maximum(first - u, u - stop), 0.0)    # 0 where the run holds the axis
    order = np.lexsort((gap, line))                           # each line's nearest run first
    lines, at = np.unique(line[order], return_index=True)
    nearest = order[at]
    close = gap[nearest] <= TRUNK_SEARCH * width
    whole = (first[nearest] > 0) & (stop[nearest] < width)
    k = seen[lines]
    out[k[close]] = np.where(whole[close], length[nearest[close]] * depth[k[close]] / view.focal[0], np.nan)
    return out


def triangulated_foot(masks: list[np.ndarray], views: list[PinholeView]) -> np.ndarray | None:
    """(3,) the trunk's foot where the rays through each photo's trunk bottom (`_trunk_pixel`) pass nearest (least
    squares; then again without the rays farther than twice the median from it: a mask that took a shadow for
    the trunk). The ground's height where SfM gave no ground plane. None with fewer than two rays."""
    starts, rays = [], []
    for mask, view in zip(masks, views):
        pixel = _trunk_pixel(mask)
        if pixel is not None:
            ray = view.rotation.T @ np.array([(pixel[0] - view.principal[0]) / view.focal[0],
                                              (pixel[1] - view.principal[1]) / view.focal[1], 1.0])
            starts.append(view.centre)
            rays.append(ray / np.linalg.norm(ray))
    if len(rays) < 2:
        return None
    starts, rays = np.array(starts), np.array(rays)
    keep = np.ones(len(rays), bool)
    for _ in range(2):
        across = np.eye(3)[None] - rays[:, :, None] * rays[:, None, :]
        try:
            foot = np.linalg.solve(across[keep].sum(axis=0), np.einsum("kij,kj->i", across[keep], starts[keep]))
        except np.linalg.LinAlgError:
            return None
        miss = np.linalg.norm(np.einsum("kij,kj->ki", across, foot - starts), axis=1)
        keep = miss <= 2.0 * np.median(miss)
        if keep.sum() < 2:
            break
    return foot


def trunk_radius_from_masks(masks: list[np.ndarray], views: list[PinholeView], root: np.ndarray,
                            breast_height: float = BREAST_HEIGHT_M) -> float | None:
    """The trunk's radius (m) at `breast_height` above `root` (3,), the trunk's foot in the views' frame, from the
    photos' tree masks: half the median over the photos of `trunk_widths` there (where a whole run was found).
    None when no photo has one. The sparse points cannot give it in leaf: their stem fit takes the crown's leaves
    for the trunk."""
    widths = np.array([trunk_widths(mask, view, root, np.array([breast_height]))[0]
                       for mask, view in zip(masks, views)])
    widths = widths[widths > 0]
    return 0.5 * float(np.median(widths)) if len(widths) else None


def crown_base_from_masks(masks: list[np.ndarray], views: list[PinholeView], foot: np.ndarray,
                          trunk_radius: float, top: float) -> float | None:
    """The height above `foot` where the crown begins: in each photo, the lowest of heights every CROWN_STEP up to
    `top` where the tree across the trunk's axis is wider than CROWN_WIDENS trunk diameters; the
    CROWN_BASE_QUANTILE of those over the photos (raised cameras see the crown's near underside hide the trunk
    below the crown's base; the lowest cameras see it highest). None when no photo shows it."""
    heights = np.arange(CROWN_STEP, top, CROWN_STEP)
    bases = []
    for mask, view in zip(masks, views):
        widths = trunk_widths(mask, view, foot, heights)
        wide = np.flatnonzero(~(widths <= CROWN_WIDENS * 2.0 * trunk_radius))   # NaN (not whole) counts as wide
        if len(wide):
            bases.append(heights[wide[0]])
    return float(np.quantile(bases, CROWN_BASE_QUANTILE)) if bases else None


def _under_crown_cleared(hull: VisualHull, foot: np.ndarray, crown_base: float, trunk_radius: float) -> VisualHull:
    """The hull without its voxels under the crown's base but the trunk's: raised cameras all look at the space
    under a wide crown across the crown itself, so no mask carves it (the hull's skirt)."""
    centres = hull.centres()                                  # in np.argwhere(occupancy) order
    under = centres[:, 2] < foot[2] + crown_base - hull.voxel_size
    off_trunk = np.linalg.norm(centres[:, :2] - foot[:2], axis=1) > max(2.0 * trunk_radius, 1.5 * hull.voxel_size)
    occupancy = hull.occupancy.copy()
    occupancy[hull.occupancy] = ~(under & off_trunk)            # boolean indexing walks the same order
    return dataclasses.replace(hull, occupancy=occupancy)


def top_unseen(hull: VisualHull) -> bool:
    """Whether `hull` fills the top layer of the box it was carved in: no photo saw the space over the crown
    outside its tree mask. From eye height near a wide crown its near side hides the top from every photo (on the
    phone walk round the 15.5 m oak, the hull rose to 33.5 m)."""
    return bool(hull.occupancy[:, :, -1].any())


def crown_proportion(preset: Preset) -> float:
    """The colonization preset's tree height over its crown's width, at their base values: (crown_base +
    crown_height) / (2 crown_radius), all in internodes."""
    ranges = preset.ranges
    return (ranges["crown_base"].base + ranges["crown_height"].base) / (2.0 * ranges["crown_radius"].base)


def crown_width(hull: VisualHull) -> float:
    """Metres: the hull's wider horizontal extent (x or y) over its occupied voxels."""
    occupied = np.argwhere(hull.occupancy)
    return float((np.ptp(occupied[:, :2], axis=0).max() + 1) * hull.voxel_size)


def hull_bounds(points: np.ndarray, ground_z: float) -> np.ndarray:
    """(2, 3) the box carved: the tree's points' box grown by HULL_MARGIN, from the ground up."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = HULL_MARGIN * float(max(hi - lo))
    return np.array([[lo[0] - pad, lo[1] - pad, ground_z], [hi[0] + pad, hi[1] + pad, hi[2] + pad]])


def ground_sightlines(sfm, tree, views: list[PinholeView], base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, ends), each (S, 3) in the upright frame: the sightlines from every camera that saw an SfM point on
    the ground (within GROUND_SIGHT_BAND of the tree's height above the ground plane) no farther than
    GROUND_SIGHT_REACH of its height from `base`, the tree's base, to that point. Ground seen near the trunk was
    seen under the crown, so its sightlines cross the space a shadow taken for the tree keeps in the masks;
    ground seen farther out was often seen through the crown's gaps, and would carve the crown. Empty when SfM
    kept no tracks."""
    if sfm.observations is None or not len(sfm.observations):
        return np.zeros((0, 3)), np.zeros((0, 3))
    to_upright = tree.model_to_upright
    seen = sfm.points @ to_upright[:3, :3].T + to_upright[:3, 3]
    height = float(tree.points[:, 2].max() - tree.ground_z)
    ground = (seen[:, 2] < tree.ground_z + GROUND_SIGHT_BAND * height) \
        & (np.linalg.norm(seen[:, :2] - base[:2], axis=1) < GROUND_SIGHT_REACH * height)
    pairs = sfm.observations[ground[sfm.observations[:, 0]]]
    centres = np.array([view.centre for view in views])
    return centres[pairs[:, 1]], seen[pairs[:, 0]]


def draw_masks(sfm, views: list[PinholeView], folder: str | Path, bounds: np.ndarray, base: np.ndarray,
               points: np.ndarray, mask_net: MaskNetwork | None) -> list[np.ndarray]:
    """Each registered photo's tree mask (`photo_mask`), the tree's window in it from `bounds`, `base` and the
    `points` on it (`tree_window`)."""
    masks = []
    for name, view in zip(sfm.registered, views):
        with Image.open(Path(folder) / name) as photo:
            image = np.asarray(photo.convert("RGB"))
        masks.append(photo_mask(image, tree_window(view, bounds, base, points), mask_net))
    return masks


def aimed_bounds(views: list[PinholeView], aim: np.ndarray, ground_z: float) -> np.ndarray:
    """(2, 3) the box carved for a tree SfM left too few points on: round `aim` (3,), where the photos aim,
    AIMED_REACH of the cameras' median horizontal distance to it on every side, from the ground `ground_z` up to
    the highest any photo's top edge (at the middle column) reaches above the aim."""
    centres = np.array([view.centre for view in views])
    reach = np.linalg.norm(centres[:, :2] - aim[:2], axis=1)
    half = AIMED_REACH * float(np.median(reach))
    tops = []
    for view, distance in zip(views, reach):
        ray = view.rotation.T @ np.array([0.0, -view.principal[1] / view.focal[1], 1.0])
        slope = ray[2] / max(float(np.linalg.norm(ray[:2])), 1e-9)
        tops.append(view.centre[2] + distance * min(slope, np.tan(np.radians(AIMED_MAX_ELEVATION_DEG))))
    top = max(max(tops), ground_z + 0.1 * half)
    return np.array([[aim[0] - half, aim[1] - half, ground_z], [aim[0] + half, aim[1] + half, top]])


def aimed_hull(sfm, tree, folder: str | Path, aim: np.ndarray, mask_net: MaskNetwork | None
               ) -> tuple[VisualHull, list[np.ndarray]]:
    """The visual hull of the photos' tree masks in `aimed_bounds` round `aim` (3,) in `tree`'s upright frame,
    and the masks: where SfM left too few points on the tree to say where it stands and how large it is."""
    views = photo_views(sfm, tree.model_to_upright)
    bounds = aimed_bounds(views, aim, tree.ground_z)
    base = np.array([aim[0], aim[1], tree.ground_z])
    masks = draw_masks(sfm, views, folder, bounds, base, tree.points, mask_net)
    return carve(masks, views, bounds, float(max(bounds[1] - bounds[0])) / HULL_VOXELS), masks


def took_hold(skeleton: Skeleton, guide: Skeleton) -> bool:
    """Whether the growth from `guide` added at least as many nodes as the guide has (else it starved)."""
    return len(skeleton) >= 2 * len(guide)


def grow_in_hull_space(params: dict, rng: np.random.Generator, occupancy: np.ndarray, space: VoxelSpace,
                       guide: Skeleton, internode: float) -> Skeleton:
    """`grow_in_space` from `guide` (its buds on every node) in `space`, the hull's voxels `occupancy` placed in
    the base frame. A hull too porous round the bole for a new internode to land in it (classical masks in leaf)
    leaves the growth no more than the guide: then it runs again on the same markers, its internodes allowed one
    voxel outside the hull, then two, up to GROWTH_REACH."""
    skeleton = grow_in_space(params, rng, space=space, internode_length=internode, guide=guide, guide_buds="all")
    markers = None
    for reach in range(1, GROWTH_REACH + 1):
        if took_hold(skeleton, guide):
            break
        if markers is None:
            markers = space.sample_markers(params["marker_density"] / internode ** 3, params["max_markers"], rng)
        wider = VoxelSpace(ndimage.binary_dilation(occupancy, iterations=reach), space.origin, space.voxel_size)
        skeleton = grow_in_space(params, rng, space=wider, internode_length=internode, guide=guide,
                                 guide_buds="all", markers=markers)
    return skeleton


def rerooted(scan: ScanRecord, root: np.ndarray) -> ScanRecord:
    """`scan` with its base frame's origin moved to `root` (3,), a point of the upright frame (the photos' scan
    frame): the transform's shift, and the measured skeleton moved the other way."""
    transform = scan.transform.copy()
    transform[:3, 3] = np.asarray(root, np.float64)
    measured = scan.measured
    step = scan.transform[:3, :3].T @ (scan.transform[:3, 3] - root)    # in the base frame's axes
    moved = (measured.positions + step).astype(measured.positions.dtype)
    return dataclasses.replace(scan, transform=transform,
                               measured=Skeleton(moved, measured.parent, measured.radius, measured.order))


def colonization_preset(species: str | None) -> Preset:
    """The colonization preset called `species` (None: DEFAULT_SPECIES); PhotoError for another or an unknown one."""
    chosen = DEFAULT_SPECIES if species is None else species
    try:
        preset = get_preset(chosen)
    except PresetError:
        raise PhotoError(f"species {chosen!r} is unknown: allowed a colonization preset (sc_*), default "
                         f"{DEFAULT_SPECIES!r}") from None
    if preset.generator != "colonization":
        raise PhotoError(f"species {chosen!r} is a {preset.generator} preset: allowed a colonization preset "
                         f"(sc_*), default {DEFAULT_SPECIES!r}")
    return preset


def grow_in_hull(result: Reconstruction, sfm, tree, folder: str | Path, *, species: str | None = None,
                 seed: int = 0, mask_net: MaskNetwork | None = None,
                 masks: tuple[np.ndarray, ...] | None = None, ceiling: float | None = None) -> Reconstruction:
    """`result` (the cloud method's, from `tree`'s points) regrown inside the photos' visual hull (module
    docstring); timings add "hull.masks", "hull.hull", "hull.growth" and "hull.mesh"; maps add "hull" (the
    `VisualHull`, upright metric frame), "masks" (each registered photo's) and "main_skeleton" (the bole it grew
    from); params are the species preset's draw it grew with.
    species : a colonization preset (sc_*), default DEFAULT_SPECIES. Raises PhotoError for a preset that is not
    a colonization one, and HullError (a PhotoError) when no photo's mask holds the tree.
    mask_net : the tree mask network that draws the photos' masks (`photo_masks.mask_network`); None: classical.
    masks    : the registered photos' masks already drawn (an earlier call's maps["masks"] on the same photos: they
               do not change with the tree's scale); None draws them.
    ceiling  : the height (z, upright frame) the hull is carved up to at most (a top no photo saw, `top_unseen`,
               cut at a given height); None: the tree's points' box.
    A hull no crown grows in (`grow_in_hull_space` gave no more than the bole) leaves the cloud method's tree, with
    the hull and masks in its maps and a warning that says so."""
    preset = colonization_preset(species)
    timer = StageTimer()
    views = photo_views(sfm, tree.model_to_upright)
    bounds = hull_bounds(tree.points, tree.ground_z)
    if ceiling is not None:
        bounds[1, 2] = min(bounds[1, 2], float(ceiling))
    base = np.array([*np.median(tree.points[:, :2], axis=0), tree.ground_z])
    if masks is None:
        masks = draw_masks(sfm, views, folder, bounds, base, tree.points, mask_net)
    timer.lap("masks")
    hull = carve(masks, views, bounds, float(max(bounds[1] - bounds[0])) / HULL_VOXELS, points=tree.points,
                 sightlines=ground_sightlines(sfm, tree, views, base))
    top = hull.top()
    foot = trunk_foot(masks, views, tree.ground_z)
    if "ground plane" not in tree.up_source:
        # a ground read off the masks' trunk bottoms (no plane among SfM's points) is a few tenths of a metre off,
        # and rays cast on it from eye height land metres off: where the rays meet is the foot
        met = triangulated_foot(masks, views)
        foot = foot if met is None else np.array([met[0], met[1], tree.ground_z])
    trunk_radius = None if foot is None else trunk_radius_from_masks(masks, views, foot)
    crown_base = None
    scan = result.scan
    shows_trunk = trunk_radius is not None and trunk_radius <= MAX_TRUNK_SHARE * (top - foot[2])
    if foot is not None and (shows_trunk or np.linalg.norm(scan.transform[:2, 3] - foot[:2])
                             > ROOT_AGREE * (top - foot[2])):
        # the tree stands on the masks' foot where they show the trunk, or where the sparse points' root lies far
        # from it (on the ground's points: 2 m off leafless, 10 m in leaf with estimated poses); in leaf, where
        # the masks join the trunk to its shadow, a root that agrees with their foot is the finer of the two
        scan = rerooted(scan, foot)
    if shows_trunk:
        # the crown begins where the masks widen
        crown_base = crown_base_from_masks(masks, views, foot, trunk_radius, top - foot[2])
        if crown_base is not None:
            hull = _under_crown_cleared(hull, foot, crown_base, trunk_radius)
    else:
        trunk_radius = scan.measures["trunk_radius_fit_m"]   # the sparse points' stem fit, as the cloud's
    shift = -scan.transform[:3, 3]                  # upright frame to the base frame (Z up already)
    height = top + float(shift[2])
    timer.lap("hull")
    rng = np.random.default_rng(seed)
    params = validate(preset.sample(rng))
    space = hull.space(shift)
    params["height"] = height
    internode = height / (params["crown_base"] + params["crown_height"])
    # The growth starts from a bole: the sparse points' trunk and main branches wander off the hull (ground
    # points leafless, stray points over the crown in leaf) and starved or misled it on every orbit measured.
    bole = params if crown_base is None else {**params, "stems": 1, "crown_base": crown_base / internode - 1.0}
    guide = bole_guide(bole, rng, internode)
    skeleton = grow_in_hull_space(params, rng, hull.occupancy, space, guide, internode)
    timer.lap("growth")
    maps = {**result.maps, "hull": hull, "masks": tuple(masks)}
    timings = {**result.timings, **{f"hull.{k}": v for k, v in timer.seconds.items()}}
    if not took_hold(skeleton, guide):
        # the masks carved a hull the growth cannot take hold in (masks that lost the tree in many photos)
        return dataclasses.replace(result, maps=maps, timings=timings, warnings=(*result.warnings, (
            f"the photos' tree masks carved a hull of {int(hull.occupancy.sum())} voxels that no crown grew in: "
            "this is the sparse points' tree; try --masks network or more photos")))
    mesh = build_mesh(skeleton, params)
    timer.lap("mesh")
    measures = {**qsm_measures(skeleton, scan.base_points), "trunk_radius_fit_m": trunk_radius}
    return dataclasses.replace(result, skeleton=skeleton, mesh=mesh, params=params,
                               scan=dataclasses.replace(scan, measures=measures),
                               timings={**timings, "hull.mesh": timer.seconds["mesh"]},
                               maps={**maps, "main_skeleton": guide.positions.astype(np.float32)})
