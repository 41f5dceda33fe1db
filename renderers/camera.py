"""Cameras and view rigs: one camera convention (OpenCV axes, pixels, metres), trees framed from their bounds.

In: a tree's points or bounds and a rig name; out: `Camera` objects that project, unproject and convert to OpenGL.

The convention (every renderer in the farm, Blender included, follows it):

- World: Z up, metres, tree base at the origin.
- `world_to_camera` (4, 4) float64 maps homogeneous world points to the camera frame in OpenCV axes:
  x right, y down, z forward (the viewing direction). Depth is z in that frame, metres, > 0 in front.
- `K` (3, 3) float64, pixels. Pixel coordinates (u, v): u to the right, v down, and the centre of the pixel in
  row i, column j is at (u, v) = (j, i) (OpenCV's convention), so a 256 px image spans u in [-0.5, 255.5].
  Perspective: (u, v) = (fx x / z + cx, fy y / z + cy). Orthographic: (u, v) = (fx x + cx, fy y + cy) with
  fx = width / (2 ortho_half_width) pixels per metre (likewise fy with the half height).
- OpenGL / pyrender: the camera looks down its -z with y up, so the camera pose (camera-to-world) is
  inverse(world_to_camera) @ diag(1, -1, -1, 1); `opengl_projection()` gives the matching 4x4 clip matrix
  (including the principal point and the half-pixel shift between the two pixel conventions).
- Azimuth a and elevation e place the camera at centre + d (sin a cos e, -cos a cos e, sin e): azimuth 0 looks
  from -Y toward +Y ("front", world X to the image right), 90 from +X ("right"), 180 from +Y ("back"),
  270 from -X ("left"); elevation lifts the camera and tilts it down at the centre. Image up is world up.

Rigs (`make_rig(name, points, size, rng)`): "tsn4" (TreeSketchNet: perspective, 40 deg vertical field of view,
the tree filling 90% of the frame height, front/right/back/left at azimuths 0/90/180/270, 10 deg elevation),
"orbit:N" or "orbit:N:E1,E2" (perspective, N azimuths 360/N apart at each elevation E, default 10 deg),
"two-view" (seed 001 / seed 000: orthographic "front" and "side" at azimuths 0 and 90, elevation 0, volume
= bounding box + 5% margin, each view framed on its own), "two-view:shared" (the same two views with one
metres-per-pixel: the larger of the two views' half extents, so that a point's image row is the same in both
views, which seed 001's equal-height matching of front and side needs; plain "two-view" gives the views
different scales when the crown is wider than the tree is tall). A ":jitter" suffix (last) perturbs each view
with the rng: azimuth +-7.5 deg, elevation +-3 deg, distance x U(0.95, 1.05) (two-view: one common azimuth
offset so the views stay orthogonal, and elevation 0 so rows still match under ":shared").
Rigs joined by "+" ("tsn4+two-view+two-view:shared": an evaluation dataset that serves every method) give each
part's cameras in turn, framed as that rig alone frames them, named "PART/VIEW" ("two-view:shared/front").
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from species.errors import TreefarmError

__all__ = ["Camera", "CameraError", "RIGS", "make_rig", "parse_rig", "look_at", "perspective_camera",
           "orthographic_camera", "orthographic_half_extent", "OPENCV_TO_OPENGL", "RIG_JOIN", "rig_parts", "TSN_FOV_DEG", "TSN_FILL",
           "ORTHO_MARGIN"]

OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])
TSN_FOV_DEG = 40.0   # vertical field of view of TreeSketchNet views (digest 4.2)
TSN_FILL = 0.9       # fraction of the frame height the tree fills
TSN_ELEVATION_DEG = 10.0
ORTHO_MARGIN = 0.05  # orthographic volume = bounding box + 5% (digest 1.8)
DEPTH_MARGIN = 0.02  # near/far planes sit this fraction of the depth range outside the tree
RIGS = ("tsn4", "orbit:N[:E1,E2,...]", "two-view[:shared]")
RIG_JOIN = "+"  # composite rigs: "tsn4+two-view:shared"


class CameraError(TreefarmError):
    """An unknown rig name, a bad camera dictionary or impossible camera values."""


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole or orthographic camera in the farm's convention (see the module docstring).

    width, height      : image size, pixels.
    K                  : (3, 3) float64, intrinsics, pixels (orthographic: pixels per metre on the diagonal).
    world_to_camera    : (4, 4) float64, world (Z up, metres) to camera (OpenCV axes: x right, y down, z forward).
    projection         : "perspective" or "orthographic".
    near, far          : metres along the viewing axis; depth01 = (depth - near) / (far - near).
    ortho_half_width, ortho_half_height : metres, half extents of an orthographic view (0 for perspective).
    name               : the view's name ("front", "az090_el10", ...).
    """

    width: int
    height: int
    K: np.ndarray
    world_to_camera: np.ndarray
    projection: str = "perspective"
    near: float = 0.1
    far: float = 100.0
    ortho_half_width: float = 0.0
    ortho_half_height: float = 0.0
    name: str = "view"

    def __post_init__(self) -> None:
        K = np.array(self.K, np.float64).reshape(3, 3)
        E = np.array(self.world_to_camera, np.float64).reshape(4, 4)
        if self.projection not in ("perspective", "orthographic"):
            raise CameraError(f"projection {self.projection!r} is unknown: allowed 'perspective', 'orthographic'")
        if not (0 < self.near < self.far):
            raise CameraError(f"near {self.near} and far {self.far} must satisfy 0 < near < far")
        if self.width < 1 or self.height < 1:
            raise CameraError(f"image size {self.width}x{self.height} must be at least 1x1 pixels")
        if self.projection == "orthographic" and (self.ortho_half_width <= 0 or self.ortho_half_height <= 0):
            raise CameraError("an orthographic camera needs ortho_half_width and ortho_half_height > 0")
        K.setflags(write=False)
        E.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "world_to_camera", E)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "near", float(self.near))
        object.__setattr__(self, "far", float(self.far))

    @property
    def is_orthographic(self) -> bool:
        return self.projection == "orthographic"

    @property
    def camera_to_world(self) -> np.ndarray:
        """(4, 4) float64, the camera pose in OpenCV axes."""
        return np.linalg.inv(self.world_to_camera)

    @property
    def position(self) -> np.ndarray:
        """(3,) float64, metres, the camera centre in the world."""
        return self.camera_to_world[:3, 3]

    def opengl_pose(self) -> np.ndarray:
        """(4, 4) float64, camera-to-world in OpenGL axes (x right, y up, looking down -z): pyrender's pose."""
        return self.camera_to_world @ OPENCV_TO_OPENGL

    def opengl_projection(self, reverse_depth: bool = False) -> np.ndarray:
        """(4, 4) float64, OpenGL clip matrix matching K, near and far for this image size.

        reverse_depth negates the depth row: a LESS depth test then keeps the farthest surface along each
        ray (the back depth of the silhouette pass) with the same rays and clipping as the normal matrix.
        """
        W, H, K, n, f = self.width, self.height, self.K, self.near, self.far
        P = np.zeros((4, 4))
        P[0, 0] = 2 * K[0, 0] / W
        P[1, 1] = 2 * K[1, 1] / H
        # OpenGL puts pixel centres at j + 0.5; OpenCV at j.
        shift_x = (2 * K[0, 2] + 1) / W - 1
        shift_y = 1 - (2 * K[1, 2] + 1) / H
        if self.is_orthographic:
            P[0, 3], P[1, 3] = shift_x, shift_y
            P[2, 2], P[2, 3], P[3, 3] = -2 / (f - n), -(f + n) / (f - n), 1.0
        else:
            P[0, 2], P[1, 2] = -shift_x, -shift_y
            P[2, 2], P[2, 3], P[3, 2] = -(f + n) / (f - n), -2 * f * n / (f - n), -1.0
        if reverse_depth:
            P[2] = -P[2]
        return P

    def depth_from_window(self, window: np.ndarray, reverse_depth: bool = False) -> np.ndarray:
        """Metric depth (metres) from OpenGL window depth in [0, 1] (as glReadPixels returns it) for this camera."""
        ndc = 2.0 * np.asarray(window, np.float64) - 1.0
        if reverse_depth:
            ndc = -ndc
        n, f = self.near, self.far
        if self.is_orthographic:
            return (0.5 * (ndc * (f - n) + f + n)).astype(np.float32)
        return (2.0 * n * f / (f + n - ndc * (f - n))).astype(np.float32)

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) float64, camera-frame coordinates (OpenCV axes, metres) of world points (N, 3)."""
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        return pts @ self.world_to_camera[:3, :3].T + self.world_to_camera[:3, 3]

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) metres -> pixels (N, 2) float64 (u, v) and depth (N,) float64 metres (camera z)."""
        cam = self.to_camera(points)
        z = cam[:, 2]
        if self.is_orthographic:
            xy = cam[:, :2]
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                xy = cam[:, :2] / z[:, None]
        pixels = xy * np.diag(self.K)[:2] + self.K[:2, 2]
        return pixels, z

    def unproject(self, pixels: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) (u, v) and depth (N,) metres -> world points (N, 3) float64 metres."""
        uv = np.asarray(pixels, np.float64).reshape(-1, 2)
        z = np.asarray(depth, np.float64).reshape(-1)
        xy = (uv - self.K[:2, 2]) / np.diag(self.K)[:2]
        if not self.is_orthographic:
            xy = xy * z[:, None]
        cam = np.concatenate([xy, z[:, None]], axis=1)
        return (cam - self.world_to_camera[:3, 3]) @ self.world_to_camera[:3, :3]

    def depth01(self, depth: np.ndarray) -> np.ndarray:
        """Depth (metres, 0 = background) -> float32 in [0, 1] between near and far; background 1."""
        d = np.asarray(depth, np.float32)
        out = np.clip((d - self.near) / (self.far - self.near), 0.0, 1.0).astype(np.float32)
        out[d <= 0] = 1.0
        return out

    def metres_per_pixel(self, depth: float | np.ndarray) -> float | np.ndarray:
        """Metres spanned by one pixel (vertically) at `depth` metres (independent of depth when orthographic)."""
        if self.is_orthographic:
            return 1.0 / self.K[1, 1]
        return np.asarray(depth) / self.K[1, 1]

    def to_dict(self) -> dict:
        """A JSON-able dictionary: K and world_to_camera as nested lists (OpenCV axes), sizes, planes."""
        return {"name": self.name, "width": self.width, "height": self.height, "K": self.K.tolist(),
                "world_to_camera": self.world_to_camera.tolist(), "projection": self.projection,
                "near": self.near, "far": self.far, "ortho_half_width": self.ortho_half_width,
                "ortho_half_height": self.ortho_half_height, "convention": "opencv"}

    @classmethod
    def from_dict(cls, data: dict) -> "Camera":
        keys = ("width", "height", "K", "world_to_camera", "projection", "near", "far")
        missing = [k for k in keys if k not in data]
        if missing:
            raise CameraError(f"camera dictionary lacks {missing}; it needs {list(keys)}")
        return cls(width=data["width"], height=data["height"], K=data["K"],
                   world_to_camera=data["world_to_camera"], projection=data["projection"],
                   near=data["near"], far=data["far"], ortho_half_width=data.get("ortho_half_width", 0.0),
                   ortho_half_height=data.get("ortho_half_height", 0.0), name=data.get("name", "view"))


# ------------------------------------------------------------------------------------------- placement
def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """(4, 4) float64 world_to_camera (OpenCV axes) of a camera at `eye` looking at `target`, image up = `up`."""
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:  # looking straight up or down: any right vector will do
        right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    E = np.eye(4)
    E[:3, :3] = R
    E[:3, 3] = -R @ eye
    return E


def view_direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """(3,) float64 unit vector from the target to the camera for an azimuth and elevation (degrees)."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.array([np.sin(a) * np.cos(e), -np.cos(a) * np.cos(e), np.sin(e)])


def _depth_planes(z_min: float, z_max: float) -> tuple[float, float]:
    span = max(z_max - z_min, 1e-3)
    return max(z_min - DEPTH_MARGIN * span, 1e-3), z_max + DEPTH_MARGIN * span


class _Columns(np.ndarray):
    """(3, N) float64 points, one coordinate per contiguous row (reductions over rows are several times faster
    than over axis 0 of (N, 3)); a distinct type so that three points in (N, 3) layout are never mistaken."""


def _columns(points: np.ndarray) -> np.ndarray:
    if isinstance(points, _Columns):
        return points
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    return np.ascontiguousarray(pts.T).view(_Columns)


def _view_frame(columns: np.ndarray, azimuth_deg: float, elevation_deg: float):
    """Box centre (3,), unit direction to the camera (3,), and |x|, |y| max-ready rows and z (camera axes,
    origin at the centre) of the points."""
    lo, hi = columns.min(axis=1), columns.max(axis=1)
    centre = 0.5 * (lo + hi)
    direction = view_direction(azimuth_deg, elevation_deg)
    R = look_at(centre + direction, centre)[:3, :3]
    rel = R @ (columns - centre[:, None])
    return centre, direction, rel


def perspective_camera(points: np.ndarray, azimuth_deg: float, elevation_deg: float, size: int,
                       fov_deg: float = TSN_FOV_DEG, fill: float = TSN_FILL, distance_scale: float = 1.0,
                       name: str = "view") -> Camera:
    """A square perspective camera looking at the box centre of `points` (N, 3) metres, framed so
    they fill `fill` of the frame (height or width, whichever binds), near/far fitted to them."""
    centre, direction, rel = _view_frame(_columns(points), azimuth_deg, elevation_deg)
    tan_half = fill * np.tan(np.radians(fov_deg) / 2)
    # The smallest distance at which every point satisfies |x| / (z + d) <= tan_half (and likewise y).
    extent = np.maximum(np.abs(rel[0]), np.abs(rel[1]))
    d = float(np.max(extent / tan_half - rel[2])) * distance_scale
    d = max(d, 1e-3)
    E = look_at(centre + d * direction, centre)
    near, far = _depth_planes(float(rel[2].min()) + d, float(rel[2].max()) + d)
    f = (size / 2) / np.tan(np.radians(fov_deg) / 2)
    K = np.array([[f, 0, (size - 1) / 2], [0, f, (size - 1) / 2], [0, 0, 1]])
    return Camera(size, size, K, E, "perspective", near, far, name=name)


def _fitted_half(rel: np.ndarray, margin: float) -> float:
    """Metres, the half extent of a square orthographic view of camera-axes points `rel` (3, N) plus `margin`."""
    half = max(float(np.abs(rel[0]).max()), float(np.abs(rel[1]).max())) * (1 + margin)
    return max(half, 1e-3)


def orthographic_half_extent(points: np.ndarray, azimuth_deg: float, elevation_deg: float,
                             margin: float = ORTHO_MARGIN) -> float:
    """Metres, the half width (= half height) `orthographic_camera` fits to `points` (N, 3) metres for a view."""
    return _fitted_half(_view_frame(_columns(points), azimuth_deg, elevation_deg)[2], margin)


def orthographic_camera(points: np.ndarray, azimuth_deg: float, elevation_deg: float, size: int,
                        margin: float = ORTHO_MARGIN, name: str = "view", half_extent: float | None = None) -> Camera:
    """A square orthographic camera whose volume is the box around `points` (N, 3) metres plus
    `margin`, centred on the box; one scale for both axes (the larger half extent binds).

    half_extent : metres, a half width (= half height) to use instead of the fitted one, so that several
                  views share one metres-per-pixel (rig "two-view:shared"); it must cover the points to keep
                  them in the frame (the larger of the views' `orthographic_half_extent` does).
    """
    centre, direction, rel = _view_frame(_columns(points), azimuth_deg, elevation_deg)
    if half_extent is None:
        half = _fitted_half(rel, margin)
    elif np.isfinite(half_extent) and half_extent > 0:
        half = float(half_extent)
    else:
        raise CameraError(f"half_extent {half_extent} must be a finite number of metres > 0")
    z_min, z_max = float(rel[2].min()), float(rel[2].max())
    d = -z_min + half  # in front of everything, with room to spare
    E = look_at(centre + d * direction, centre)
    near, far = _depth_planes(z_min + d, z_max + d)
    s = size / (2 * half)
    K = np.array([[s, 0, (size - 1) / 2], [0, s, (size - 1) / 2], [0, 0, 1]])
    return Camera(size, size, K, E, "orthographic", near, far, half, half, name=name)


# ------------------------------------------------------------------------------------------------ rigs
@dataclass(frozen=True)
class RigSpec:
    """A parsed rig name: kind, projection, the (name, azimuth, elevation) of each view, jitter, and whether
    the (orthographic) views share one scale ("two-view:shared")."""

    kind: str
    projection: str
    views: tuple[tuple[str, float, float], ...]
    jitter: bool
    shared_scale: bool = False


def rig_parts(rig: str) -> list[str]:
    """The rigs a (possibly composite, "+"-joined) rig name is made of, each checked by `parse_rig`."""
    if not isinstance(rig, str) or not rig:
        raise CameraError(f"rig {rig!r} is unknown: allowed {', '.join(RIGS)} (optionally with ':jitter')")
    parts = [part.strip() for part in rig.split(RIG_JOIN)]
    if len(set(parts)) < len(parts):
        raise CameraError(f"rig {rig!r} names a rig twice: allowed distinct rigs joined by {RIG_JOIN!r}")
    for part in parts:
        parse_rig(part)
    return parts


def parse_rig(rig: str) -> RigSpec:
    """Parse "tsn4", "orbit:N", "orbit:N:E1,E2", "two-view", "two-view:shared", each optionally followed by
    ":jitter". A composite ("+"-joined) rig is checked part by part with `rig_parts`."""
    if not isinstance(rig, str) or not rig:
        raise CameraError(f"rig {rig!r} is unknown: allowed {', '.join(RIGS)} (optionally with ':jitter')")
    parts = rig.split(":")
    jitter = parts[-1] == "jitter"
    if jitter:
        parts = parts[:-1]
    kind = parts[0] if parts else ""
    bad = CameraError(f"rig {rig!r} is unknown: allowed {', '.join(RIGS)} (optionally with ':jitter')")
    if kind == "tsn4" and len(parts) == 1:
        views = tuple((n, a, TSN_ELEVATION_DEG) for n, a in
                      (("front", 0.0), ("right", 90.0), ("back", 180.0), ("left", 270.0)))
        return RigSpec(kind, "perspective", views, jitter)
    if kind == "two-view" and (len(parts) == 1 or parts[1:] == ["shared"]):
        return RigSpec(kind, "orthographic", (("front", 0.0, 0.0), ("side", 90.0, 0.0)), jitter,
                       shared_scale=len(parts) == 2)
    if kind == "orbit" and len(parts) in (2, 3):
        try:
            n = int(parts[1])
            elevations = [float(e) for e in parts[2].split(",")] if len(parts) == 3 else [TSN_ELEVATION_DEG]
        except ValueError:
            raise bad from None
        if not 1 <= n <= 360 or any(not -89.0 <= e <= 89.0 for e in elevations):
            raise CameraError(f"rig {rig!r}: orbit needs 1 <= N <= 360 views and elevations in [-89, 89] deg "
                              f"(allowed rigs: {', '.join(RIGS)})")
        views = tuple((f"az{round(a):03d}_el{round(e):+03d}", a, e)
                      for e in elevations for a in np.arange(n) * 360.0 / n)
        return RigSpec(kind, "perspective", views, jitter)
    raise bad


def make_rig(rig: str, points: np.ndarray, size: int, rng: np.random.Generator) -> list[Camera]:
    """The cameras of a rig around a tree given by `points` (N, 3) metres (vertices or bounds corners).

    The rng is used only with ":jitter" (and then drawn in view order), so a plain rig is the same for any rng.
    A composite rig gives each part's cameras in turn, named "PART/VIEW".
    """
    parts = rig_parts(rig)
    if len(parts) > 1:
        return [replace(camera, name=f"{part}/{camera.name}")
                for part in parts for camera in make_rig(part, points, size, rng)]
    spec = parse_rig(rig)
    if int(size) < 8:
        raise CameraError(f"image size {size} is too small: allowed 8 pixels or more")
    n = len(spec.views)
    d_az = np.zeros(n)
    d_el = np.zeros(n)
    scale = np.ones(n)
    if spec.jitter:
        if spec.kind == "two-view":
            d_az[:] = rng.uniform(-7.5, 7.5)
        else:
            d_az = rng.uniform(-7.5, 7.5, n)
            d_el = rng.uniform(-3.0, 3.0, n)
            scale = rng.uniform(0.95, 1.05, n)
    columns = _columns(points)
    angles = [(azimuth + d_az[i], elevation + d_el[i]) for i, (_, azimuth, elevation) in enumerate(spec.views)]
    # One half extent for every view: equal pixel scales, and (elevation 0, one box centre) equal rows.
    half = max(orthographic_half_extent(columns, az, el) for az, el in angles) if spec.shared_scale else None
    cameras = []
    for i, ((name, _, _), (az, el)) in enumerate(zip(spec.views, angles)):
        if spec.projection == "orthographic":
            cameras.append(orthographic_camera(columns, az, el, int(size), name=name, half_extent=half))
        else:
            cameras.append(perspective_camera(columns, az, el, int(size), distance_scale=scale[i], name=name))
    return cameras
