"""Photos to points with pycolmap (issue 24, first stage): SIFT features, matching, and either incremental mapping
or, when the folder's `cameras.json` gives every photo's pose, triangulation at those poses.

In: a folder of photos (IMAGE_SUFFIXES), optionally with the `cameras.json` our Blender renders write (OpenCV axes,
world Z up in metres: COLMAP's own camera convention, so the poses go in as they are). Out: `SfmPoints`, the
triangulated points with their colours in the cameras' world frame; `reconstruct.from_photos` makes them upright
and metric, isolates the tree and grows it (docs/reconstruct.md records what was measured).

Pixel centres: OpenCV puts pixel (0, 0)'s centre at (0, 0), COLMAP at (0.5, 0.5), so a known principal point moves
by half a pixel on the way in.

Same photos and seed, same points, on any number of threads up to the mapping: the photos enter COLMAP's database
in name order before the threads extract their features (otherwise the first to finish is numbered first), and
each pair's verification RANSAC is seeded from `SfmSettings.seed` (otherwise it draws from the random state of
whichever thread takes the pair). Triangulation at known poses is then the same bytes too. Incremental mapping is
seeded as well, but with more than one thread an estimated model can still differ run to run where it needs
COLMAP's structure-less registration (a RANSAC run in parallel) or a bundle adjustment large enough to be
multi-threaded; one thread (`threads=1`, COLMAP's own advice) is the way to the same bytes there, at a cost in
time (docs/reconstruct.md).
"""
from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import pycolmap

from renderers.camera import Camera, CameraError
from species.timing import StageTimer

from .photo_folder import IMAGE_SUFFIXES, MIN_PHOTOS, PhotoError, check_readable, photo_names

__all__ = ["PhotoError", "SfmSettings", "SfmPoints", "sfm_points", "photo_names", "known_cameras",
           "align_to_cameras", "IMAGE_SUFFIXES", "MIN_PHOTOS", "Progress", "no_progress"]

# progress(stage, done, total): SfM's stages in order, "features" and "matching" (photos), then "mapping" (photos
# registered, over every attempt) or "triangulation"; `from_photos` adds "tree" (isolation, skeleton, mesh).
Progress = Callable[[str, int, int], None]
MIN_KEYPOINTS = 15      # COLMAP's least inlier matches of a verified pair (min_num_inliers): fewer link nothing

MATCHERS = ("auto", "exhaustive", "sequential")
POSES = ("auto", "known", "estimate")


@dataclass(frozen=True)
class SfmSettings:
    """pycolmap's options that matter for tree photos.

    max_image_size : pixels, the longer side SIFT sees. max_features : per photo. peak_threshold : SIFT's contrast
                     floor (COLMAP's default 0.0067). max_ratio : the nearest/second-nearest descriptor distance
                     ratio a match may have (COLMAP's 0.8). guided : guided matching (more matches along the
                     verified epipolar lines). The three defaults are loosened for trees: leaves give weak,
                     repetitive features, and COLMAP's defaults leave few points above the ground; the loosened
                     ones cost more time (docs/performance.md has what they gave on renders at known poses).
    matcher        : "exhaustive" (every pair), "sequential" (each photo with the next `overlap`, for orbits and
                     walks) or "auto" (exhaustive up to `exhaustive_max` photos).
    poses          : "known" (cameras.json, triangulation only), "estimate" (incremental mapping) or "auto"
                     (known when cameras.json lists every photo).
    min_registered : the share of photos the model must hold. threads : 0 = all CPUs (estimated poses may then
                     differ run to run: the module docstring says where). seed : pycolmap's PRNG and RANSACs.
    mapping_attempts : incremental mappings tried with estimated poses, seeded seed, seed + 1, ...; the model
                     with the most registered photos, then the most points, is kept. Which initial pair and
                     RANSAC draws a seed gives depends on the CPU's floating point: on ten test renders one seed
                     gave 447 points and poses 3.2 m off on one machine, the next two 470 and 606 points, 0.7 and
                     0.28 m (0.28 m is what seed 0 gave on another).
    mapping_budget_s : seconds all the mapping attempts may take together: a later attempt starts only while some
                     are left, and each stops (COLMAP's max_runtime_seconds) when they run out, keeping the model it
                     has. Sparse photos that COLMAP registers one by one through its structure-less fallback took
                     2.5-5 minutes an attempt (twelve 720 x 1280 photos walked round a tree); the orbits' attempts
                     take under a minute and never meet it. A run that meets it depends on the machine's speed.
    """

    max_image_size: int = 1600
    max_features: int = 8192
    peak_threshold: float = 0.002
    max_ratio: float = 0.9
    guided: bool = True
    matcher: str = "auto"
    exhaustive_max: int = 60
    overlap: int = 10
    poses: str = "auto"
    min_registered: float = 0.5
    threads: int = 0
    seed: int = 0
    mapping_attempts: int = 3
    mapping_budget_s: float = 360.0

    def __post_init__(self) -> None:
        if self.matcher not in MATCHERS:
            raise PhotoError(f"matcher {self.matcher!r} is unknown: allowed {', '.join(MATCHERS)}")
        if self.poses not in POSES:
            raise PhotoError(f"poses {self.poses!r} is unknown: allowed {', '.join(POSES)}")
        if not 0.0 < self.max_ratio <= 1.0:
            raise PhotoError(f"max_ratio {self.max_ratio!r} is out of range: allowed (0, 1]")
        if not self.peak_threshold > 0.0:
            raise PhotoError(f"peak_threshold {self.peak_threshold!r} is out of range: allowed > 0")
        if isinstance(self.mapping_attempts, bool) or not isinstance(self.mapping_attempts, int) \
                or not 1 <= self.mapping_attempts <= 20:
            raise PhotoError(f"mapping_attempts {self.mapping_attempts!r} is out of range: allowed an integer in "
                             f"[1, 20]")
        if not (isinstance(self.mapping_budget_s, (int, float)) and self.mapping_budget_s >= 1.0):
            raise PhotoError(f"mapping_budget_s {self.mapping_budget_s!r} is out of range: allowed seconds >= 1")
        if not 0.0 < self.min_registered <= 1.0:
            raise PhotoError(f"min_registered {self.min_registered!r} is out of range: allowed (0, 1]")
        for name in ("max_image_size", "max_features", "exhaustive_max", "overlap"):
            if int(getattr(self, name)) < 1:
                raise PhotoError(f"{name} {getattr(self, name)!r} is too small: allowed 1 or more")


@dataclass(frozen=True, eq=False)
class SfmPoints:
    """What SfM made of a folder.

    points  : (N, 3) float64, the model's frame (known poses: the cameras' world, Z up, metres).
    colours : (N, 3) uint8. track_length : (N,) int, photos that see each point.
    registered : names of the photos in the model (sorted), of `n_photos`. poses : "known", "estimated" or
    "aligned" (estimated, then moved onto cameras.json's centres by `align_to_cameras`).
    reprojection_px : mean reprojection error. camera_centres : (R, 3) float64, of `registered` in that order;
    camera_rotations : (R, 3, 3) float64, their world-to-camera rotations (OpenCV axes).
    half_widths : (R,) float64, each photo's half width over its focal length (tan of half the horizontal view).
    intrinsics : (R, 3, 3) float64, each photo's pinhole matrix (COLMAP's pixel centres: pixel (0, 0) spans
    [0, 1)); sizes : (R, 2) int, (width, height) pixels. Lens distortion is left out.
    observations : (T, 2) int, (point, photo) index pairs: which registered photos saw each point (its track), in
    point order; the sightlines from those cameras to the point cross free space.
    """

    points: np.ndarray
    colours: np.ndarray
    track_length: np.ndarray
    registered: list[str]
    n_photos: int
    poses: str
    reprojection_px: float
    camera_centres: np.ndarray
    camera_rotations: np.ndarray
    half_widths: np.ndarray
    timings: dict[str, float]
    intrinsics: np.ndarray | None = None
    sizes: np.ndarray | None = None
    observations: np.ndarray | None = None


def align_to_cameras(sfm: SfmPoints, cameras: dict[str, Camera]) -> tuple[SfmPoints, float]:
    """An estimated model moved into cameras.json's world (Z up, metres); returns it and the camera centres' RMS
    residual after the move, metres.

    The rotation is the chordal mean of the cameras' own (known.T @ estimated, one per photo), which an orbit's
    orientations fix well; the centres alone leave it loose when they lie on a short arc. Scale and shift then
    come from the centres by least squares.
    """
    known = [cameras[name] for name in sfm.registered]
    known_centres = np.array([camera.position for camera in known])
    u, _, vt = np.linalg.svd(sum(camera.world_to_camera[:3, :3].T @ R
                                 for camera, R in zip(known, sfm.camera_rotations)))
    rotation = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    turned = sfm.camera_centres @ rotation.T
    a, b = turned - turned.mean(axis=0), known_centres - known_centres.mean(axis=0)
    if (a ** 2).sum() <= 0:
        raise PhotoError("the camera centres coincide: allowed photos taken from different places")
    scale = float((a * b).sum() / (a ** 2).sum())
    shift = known_centres.mean(axis=0) - scale * turned.mean(axis=0)
    move = lambda p: scale * p @ rotation.T + shift  # noqa: E731
    centres = move(sfm.camera_centres)
    residual = float(np.sqrt(((centres - known_centres) ** 2).sum(axis=1).mean()))
    rotations = sfm.camera_rotations @ rotation.T
    return (SfmPoints(move(sfm.points), sfm.colours, sfm.track_length, sfm.registered, sfm.n_photos, "aligned",
                      sfm.reprojection_px, centres, rotations, sfm.half_widths, sfm.timings, sfm.intrinsics,
                      sfm.sizes, sfm.observations), residual)


def known_cameras(folder: str | Path, names: list[str]) -> dict[str, Camera] | None:
    """`cameras.json`'s camera for every photo, or None when the file is absent or misses a photo; PhotoError when
    it exists but is not our convention, cannot be read, or holds an orthographic view."""
    path = Path(folder) / "cameras.json"
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
        records = {v["image"]: v for v in data["views"]}
    except (ValueError, KeyError, TypeError) as error:
        raise PhotoError(f"{path} cannot be read as camera poses ({error}): allowed the cameras.json that "
                         f"`farm render --backend blender` writes") from None
    if data.get("convention") != "opencv":
        raise PhotoError(f"{path} has convention {data.get('convention')!r}: allowed 'opencv'")
    if not set(names) <= set(records):
        return None
    try:
        cameras = {name: Camera.from_dict(records[name]) for name in names}
    except CameraError as error:
        raise PhotoError(f"{path}: {error}") from None
    for name, camera in cameras.items():
        if camera.is_orthographic:
            raise PhotoError(f"{path}: {name} is orthographic: SfM allowed perspective photos only")
    return cameras


def _pinhole_params(camera: Camera) -> tuple[float, float, float, float]:
    """COLMAP's PINHOLE (fx, fy, cx, cy): the principal point half a pixel on, to COLMAP's pixel centres."""
    K = camera.K
    return float(K[0, 0]), float(K[1, 1]), float(K[0, 2]) + 0.5, float(K[1, 2]) + 0.5


def sfm_points(folder: str | Path, settings: SfmSettings | None = None, *, workdir: str | Path | None = None,
               log: str | Path | None = None, progress: Progress | None = None) -> SfmPoints:
    """The points SfM triangulates from the photos in `folder` (see the module docstring).

    workdir  : where COLMAP's database and model go (kept); by default a temporary folder, removed after.
    log      : a file COLMAP's log is appended to (it writes on the process's stdout and stderr, which are sent
               there while it runs); None leaves it on them.
    progress : told each stage's progress (`Progress`).
    Raises PhotoError for a missing folder, too few photos, one that cannot be read, a bad cameras.json, too few
    photos with features or linked by matching (said before the next stage starts), or a model that registers
    fewer than `settings.min_registered` of the photos.
    """
    settings = SfmSettings() if settings is None else settings
    names = photo_names(folder)
    check_readable(folder, names)
    cameras = known_cameras(folder, names) if settings.poses != "estimate" else None
    if settings.poses == "known" and cameras is None:
        raise PhotoError(f"poses 'known' needs {Path(folder) / 'cameras.json'} listing every photo: allowed "
                         "poses 'estimate' or 'auto' without it")
    progress = progress or no_progress
    with _output_to(log):
        if workdir is None:
            with tempfile.TemporaryDirectory(prefix="treefarm-sfm-") as tmp:
                return _run(Path(folder), names, cameras, settings, Path(tmp), progress)
        workdir = Path(workdir)
        workdir.mkdir(parents=True, exist_ok=True)
        return _run(Path(folder), names, cameras, settings, workdir, progress)


def no_progress(stage: str, done: int, total: int) -> None:
    """A `Progress` that is told nothing worth showing (no progress asked for)."""


@contextmanager
def _output_to(log: str | Path | None) -> Iterator[None]:
    """The process's stdout and stderr (file descriptors 1 and 2, where COLMAP's glog and prints go) appended to
    `log` for the block, then restored; nothing changes with None."""
    if log is None:
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    try:
        with open(log, "ab") as handle:
            os.dup2(handle.fileno(), 1)
            os.dup2(handle.fileno(), 2)
            try:
                yield
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os.dup2(saved[0], 1)
                os.dup2(saved[1], 2)
    finally:
        os.close(saved[0])
        os.close(saved[1])


def _needed(settings: SfmSettings, n_photos: int) -> int:
    """The photos a model must hold (`settings.min_registered` of them, at least MIN_PHOTOS)."""
    return max(MIN_PHOTOS, math.ceil(settings.min_registered * n_photos))


def _with_features(database: Path) -> int:
    """How many photos in the database have at least MIN_KEYPOINTS features."""
    db = pycolmap.Database.open(database)
    try:
        return sum(db.num_keypoints_for_image(image.image_id) >= MIN_KEYPOINTS for image in db.read_all_images())
    finally:
        db.close()


def _linked(database: Path) -> int:
    """How many photos matching linked to another (a verified pair with at least MIN_KEYPOINTS inlier matches)."""
    db = pycolmap.Database.open(database)
    try:
        pair_ids, geometries = db.read_two_view_geometries()
    finally:
        db.close()
    photos = set()
    for pair_id, geometry in zip(pair_ids, geometries):
        if len(geometry.inlier_matches) >= MIN_KEYPOINTS:
            photos.update(pycolmap.pair_id_to_image_pair(pair_id))
    return len(photos)


def _run(folder: Path, names: list[str], cameras: dict[str, Camera] | None, settings: SfmSettings,
         work: Path, progress: Progress) -> SfmPoints:
    timer = StageTimer()
    needed = _needed(settings, len(names))
    advice = "take more photos with more overlap (about 10 degrees apart round the tree), or give cameras.json"
    pycolmap.set_random_seed(int(settings.seed))
    database = work / "database.db"
    database.unlink(missing_ok=True)
    threads = int(settings.threads) or -1
    reader = pycolmap.ImageReaderOptions()
    mode = pycolmap.CameraMode.AUTO
    if cameras is not None:
        params = {_pinhole_params(camera) for camera in cameras.values()}
        if len(params) == 1:
            reader.camera_model, mode = "PINHOLE", pycolmap.CameraMode.SINGLE
            reader.camera_params = ",".join(repr(v) for v in params.pop())
        else:
            reader.camera_model, mode = "PINHOLE", pycolmap.CameraMode.PER_IMAGE
    else:
        reader.camera_model = "SIMPLE_RADIAL"
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = threads
    extraction.max_image_size = int(settings.max_image_size)
    extraction.sift.max_num_features = int(settings.max_features)
    extraction.sift.peak_threshold = float(settings.peak_threshold)
    progress("features", 0, len(names))
    # The photos go into the database first, one by one in name order: the extractor's threads would otherwise
    # number them in the order they finish, and matching and mapping follow the numbers.
    pycolmap.Database.open(database).close()
    pycolmap.import_images(database, folder, camera_mode=mode, image_names=names, options=reader)
    pycolmap.extract_features(database, folder, image_names=names, camera_mode=mode, reader_options=reader,
                              extraction_options=extraction, device=pycolmap.Device.cpu)
    progress("features", len(names), len(names))
    featured = _with_features(database)
    if featured < needed:
        raise PhotoError(f"{folder}: {featured} of {len(names)} photos have {MIN_KEYPOINTS} features or more: "
                         f"allowed at least {needed} ({settings.min_registered:.0%}); photos of the tree in focus, "
                         "with texture (not blank, blurred or overexposed)")
    if cameras is not None and mode == pycolmap.CameraMode.PER_IMAGE:
        _set_known_intrinsics(database, cameras)
    timer.lap("features")
    progress("matching", 0, len(names))
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = threads
    matching.guided_matching = bool(settings.guided)
    matching.sift.max_ratio = float(settings.max_ratio)
    verification = pycolmap.TwoViewGeometryOptions()
    # each pair's RANSAC seeded alike: unseeded, a thread's random state runs on over whichever pairs it takes
    verification.ransac.random_seed = int(settings.seed)
    exhaustive = settings.matcher == "exhaustive" or (settings.matcher == "auto"
                                                      and len(names) <= settings.exhaustive_max)
    if exhaustive:
        pycolmap.match_exhaustive(database, matching_options=matching, verification_options=verification,
                                  device=pycolmap.Device.cpu)
    else:
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = int(settings.overlap)
        pycolmap.match_sequential(database, matching_options=matching, pairing_options=pairing,
                                  verification_options=verification, device=pycolmap.Device.cpu)
    linked = _linked(database)
    progress("matching", len(names), len(names))
    if linked < needed:
        raise PhotoError(f"{folder}: matching linked {linked} of {len(names)} photos: allowed at least {needed} "
                         f"({settings.min_registered:.0%}); {advice}")
    timer.lap("matching")
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = threads
    _seed_mapping(options, int(settings.seed))
    model_dir = work / "model"
    model_dir.mkdir(exist_ok=True)
    if cameras is not None:
        # one thread: the triangulator and its bundle adjustment are a small share of SfM's seconds here (0.1 of
        # 3 s on ten 320 px photos), and on one thread no RANSAC draws from a pooled thread's random state
        options.num_threads = 1
        progress("triangulation", 0, 1)
        model = pycolmap.triangulate_points(_posed_reconstruction(database, cameras), database, folder,
                                            model_dir, options=options)
        progress("triangulation", 1, 1)
        poses = "known"
    else:
        candidates = []
        attempts = int(settings.mapping_attempts)
        registered = [0]  # photos registered so far, over the attempts

        def registered_one() -> None:
            registered[0] += 1
            progress("mapping", registered[0], attempts * len(names))

        mapping_started = time.perf_counter()
        for attempt in range(attempts):
            left = float(settings.mapping_budget_s) - (time.perf_counter() - mapping_started)
            if attempt and left < 1.0:
                break
            options.max_runtime_seconds = max(1, int(left))
            registered[0] = attempt * len(names)
            progress("mapping", registered[0], attempts * len(names))
            seed = int(settings.seed) + attempt
            pycolmap.set_random_seed(seed)
            _seed_mapping(options, seed)
            attempt_dir = model_dir / f"attempt_{attempt}"
            attempt_dir.mkdir(exist_ok=True)
            candidates += pycolmap.incremental_mapping(database, folder, attempt_dir, options=options,
                                                       next_image_callback=registered_one).values()
        progress("mapping", attempts * len(names), attempts * len(names))
        model = max(candidates, key=lambda m: (m.num_reg_images(), m.num_points3D()), default=None)
        poses = "estimated"
    timer.lap("mapping" if poses == "estimated" else "triangulation")
    registered = 0 if model is None else model.num_reg_images()
    if registered < needed or model.num_points3D() == 0:
        raise PhotoError(f"{folder}: SfM registered {registered} of {len(names)} photos"
                         f"{'' if model is None else f' with {model.num_points3D()} points'}: allowed at least "
                         f"{needed} ({settings.min_registered:.0%}); {advice}")
    points = list(model.points3D.values())
    images = sorted((model.image(i) for i in model.reg_image_ids()), key=lambda image: image.name)
    photo_index = {image.image_id: k for k, image in enumerate(images)}
    observations = np.array([(k, photo_index[element.image_id]) for k, p in enumerate(points)
                             for element in p.track.elements], np.int64).reshape(-1, 2)
    return SfmPoints(points=np.array([p.xyz for p in points], np.float64).reshape(-1, 3),
                     colours=np.array([p.color for p in points], np.uint8).reshape(-1, 3),
                     track_length=np.array([p.track.length() for p in points], np.int64),
                     registered=[image.name for image in images], n_photos=len(names), poses=poses,
                     reprojection_px=float(model.compute_mean_reprojection_error()),
                     camera_centres=np.array([image.projection_center() for image in images], np.float64),
                     camera_rotations=np.array([image.cam_from_world().rotation.matrix() for image in images],
                                               np.float64),
                     half_widths=np.array([0.5 * model.camera(image.camera_id).width
                                           / model.camera(image.camera_id).mean_focal_length() for image in images],
                                          np.float64),
                     timings=timer.seconds,
                     intrinsics=np.array([model.camera(image.camera_id).calibration_matrix() for image in images],
                                         np.float64).reshape(-1, 3, 3),
                     sizes=np.array([(model.camera(image.camera_id).width, model.camera(image.camera_id).height)
                                     for image in images], np.int64).reshape(-1, 2),
                     observations=observations)


def _seed_mapping(options: pycolmap.IncrementalPipelineOptions, seed: int) -> None:
    """The mapping's seed in the pipeline and in its mapper's and triangulator's own options: left at -1 there,
    their RANSACs draw from the random state of the thread they run on, which a pooled thread carries over from
    earlier work."""
    options.random_seed = seed
    options.mapper.random_seed = seed
    options.triangulation.random_seed = seed


def _set_known_intrinsics(database: Path, cameras: dict[str, Camera]) -> None:
    """Per-photo pinhole intrinsics from cameras.json into the database (photos of different sizes or lenses)."""
    db = pycolmap.Database.open(database)
    try:
        for image in db.read_all_images():
            camera = db.read_camera(image.camera_id)
            camera.params = list(_pinhole_params(cameras[image.name]))
            db.update_camera(camera)
    finally:
        db.close()


def _posed_reconstruction(database: Path, cameras: dict[str, Camera]):
    """A model holding the database's cameras and photos at their cameras.json poses, and no points."""
    model = pycolmap.Reconstruction()
    db = pycolmap.Database.open(database)
    try:
        for camera in db.read_all_cameras():
            model.add_camera_with_trivial_rig(camera)
        for image in db.read_all_images():
            E = cameras[image.name].world_to_camera
            pose = pycolmap.Rigid3d(pycolmap.Rotation3d(E[:3, :3]), E[:3, 3])
            model.add_image_with_trivial_frame(
                pycolmap.Image(name=image.name, camera_id=image.camera_id, image_id=image.image_id), pose)
    finally:
        db.close()
    return model
