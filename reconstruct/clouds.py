"""Point clouds in (issue 24's first stage): `.xyz`/`.txt`/`.csv` text, `.ply`, `.las`/`.laz`, or an (N, 3) array, with
any declared up axis, turned into the frame the skeleton code works in: Z up, metres, float32, near the origin.

Georeferenced scans carry coordinates in the millions of metres, where float32 keeps only decimetres; so the cloud is
read in float64, rotated to Z up, and recentred (the box centre in X and Y, the lowest point in Z) before anything
becomes float32, and the offset is kept to put results back in the scan's frame. Bad input (a missing or unknown
file, non-numeric or non-finite rows, too few points, no vertical extent, an unknown up axis) is a `CloudError`
whose one line names the value and what is allowed.
"""
from __future__ import annotations

import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from species.errors import TreefarmError

__all__ = ["PointCloud", "CloudError", "read_cloud", "to_z_up", "UP_AXES", "CLOUD_SUFFIXES", "MIN_POINTS"]

CLOUD_SUFFIXES = (".xyz", ".txt", ".csv", ".pts", ".ply", ".las", ".laz")
MIN_POINTS = 100            # fewer cannot describe a trunk and branches
MIN_HEIGHT_M = 0.05         # a cloud flatter than this has no vertical extent to grow a tree along
# Rotations taking the declared up axis to +Z, each a proper rotation (determinant +1), so a scan is never mirrored.
UP_AXES = {
    "z": np.eye(3),
    "-z": np.diag([1.0, -1.0, -1.0]),
    "y": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
    "-y": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
    "x": np.array([[0.0, 1, 0], [0, 0, 1], [1, 0, 0]]),
    "-x": np.array([[0.0, -1, 0], [0, 0, 1], [-1, 0, 0]]),
}


class CloudError(TreefarmError):
    """A point cloud that cannot be read or cannot be a tree; the message names the value and what is allowed."""


@dataclass(frozen=True, eq=False)
class PointCloud:
    """A cloud in the working frame.

    points : (N, 3) float32 metres, Z up, the box centre at X = Y = 0 and the lowest point at Z = 0.
    offset : (3,) float64, what was subtracted after the rotation to Z up: scan frame = up_rotation.T @ (points +
             offset), computed in float64.
    up     : the declared up axis of the source ("z", "-y", ...); up_rotation : (3, 3) float64 taking it to +Z.
    colours: (N, 3) uint8 or None. source : the file's path, or "array".
    """

    points: np.ndarray
    offset: np.ndarray
    up: str
    up_rotation: np.ndarray
    colours: np.ndarray | None
    source: str

    @property
    def height(self) -> float:
        """Metres from the lowest to the highest point."""
        return float(self.points[:, 2].max())

    def to_scan_frame(self, points: np.ndarray) -> np.ndarray:
        """(M, 3) float64: working-frame points (a skeleton's, a mesh's) back in the source's frame."""
        return (np.asarray(points, np.float64) + self.offset) @ self.up_rotation


def to_z_up(points: np.ndarray, up: str) -> np.ndarray:
    """(N, 3) float64 points with the declared up axis turned to +Z (see UP_AXES)."""
    if up not in UP_AXES:
        raise CloudError(f"up axis {up!r} is unknown: allowed {', '.join(UP_AXES)}")
    return np.asarray(points, np.float64) @ UP_AXES[up].T


def _text_separator(path: Path) -> str | None:
    """"," or ";" when the first line holds one, else None (any run of whitespace)."""
    with path.open("r", errors="replace") as handle:
        first = handle.readline()
    return "," if "," in first else (";" if ";" in first else None)


def _first_bad_row(path: Path, separator: str | None) -> CloudError:
    """The error naming the first row (1-based, as the file counts its lines) whose first three fields are not
    three numbers, or the column count when every row is short. Read line by line: only a refused file comes here."""
    widths = set()
    with path.open("r", errors="replace") as handle:
        for number, line in enumerate(handle, 1):
            text = line.split("#", 1)[0].strip()
            if not text:
                continue
            fields = text.split(separator)
            widths.add(len(fields))
            if not all(_is_number(field) for field in fields[:3]) or (len(fields) < 3 and len(widths) > 1):
                return CloudError(f"{path} row {number} is {' '.join(fields[:3])!r}: allowed three numbers x y z "
                                  "per row")
    if widths and max(widths) < 3:
        return CloudError(f"{path} has {max(widths)} column(s): allowed rows of at least x y z")
    return CloudError(f"{path} is not a text point cloud: allowed rows of x y z [r g b ...] numbers")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _text_points(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """x y z, and colours where columns 4-6 of every row are integers 0-255; blank lines and # comments skipped.
    numpy's own reader: a cloud run loads no table library (the command's start-up time)."""
    separator = _text_separator(path)
    try:
        with warnings.catch_warnings():  # an empty file: refused below with the file's name, not warned about
            warnings.simplefilter("ignore", UserWarning)
            table = np.loadtxt(path, delimiter=separator, comments="#", dtype=np.float64, ndmin=2)
    except ValueError:
        try:  # rows of differing widths: their x y z still count, their colours do not
            table = np.loadtxt(path, delimiter=separator, comments="#", dtype=np.float64, ndmin=2, usecols=(0, 1, 2))
        except (ValueError, IndexError):
            raise _first_bad_row(path, separator) from None
    if table.shape[1] < 3:
        raise _first_bad_row(path, separator)
    colours = None
    if table.shape[1] >= 6:
        rgb = table[:, 3:6]
        if np.isfinite(rgb).all() and rgb.min() >= 0 and rgb.max() <= 255 and np.all(rgb == np.round(rgb)):
            colours = rgb.astype(np.uint8)
    return table[:, :3].copy(), colours


def _ply_points(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    import trimesh

    try:
        loaded = trimesh.load(path, process=False)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for a broken file
        raise CloudError(f"{path} is not a readable PLY ({type(exc).__name__}: {exc}): allowed a PLY of vertices") \
            from None
    vertices = np.asarray(getattr(loaded, "vertices", np.empty((0, 3))), np.float64)
    colours = getattr(loaded, "colors", None)
    if colours is None and hasattr(loaded, "visual") and getattr(loaded.visual, "kind", None) == "vertex":
        colours = loaded.visual.vertex_colors
    colours = None if colours is None or len(colours) != len(vertices) else np.asarray(colours)[:, :3].astype(np.uint8)
    return vertices, colours


# An uncompressed LAS file's public header (ASPRS LAS 1.0-1.4): where its fields start, and its least size by minor
# version; a point format's least record size, and where red (then green, blue: uint16) starts in the formats that
# have colours. Every record starts with X Y Z as int32, scaled and offset by the header's float64 triples.
_LAS_HEADER_FIELDS = {"minor": (25, "<B"), "header_size": (94, "<H"), "point_offset": (96, "<I"),
                      "format": (104, "<B"), "record_size": (105, "<H"), "count": (107, "<I"), "scales": (131, "<3d"),
                      "offsets": (155, "<3d"), "count_64": (247, "<Q")}
_LAS_HEADER_SIZES = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}
_LAS_RECORD_SIZES = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}
_LAS_RED_AT = {2: 20, 3: 28, 5: 28, 7: 30, 8: 30, 10: 30}


def _plain_las_points(path: Path) -> tuple[np.ndarray, np.ndarray | None] | None:
    """`_las_points` of an uncompressed LAS file (versions 1.0-1.4, point formats 0-10), read by numpy from the
    header's fields; None for anything else (LAZ, another version, a header or file shorter than it says), which
    laspy reads or refuses. Here, not by laspy, for the command's start-up time: laspy imports an HTTP client."""
    with path.open("rb") as handle:
        header = handle.read(_LAS_HEADER_SIZES[4])
    if len(header) < _LAS_HEADER_SIZES[0] or header[:4] != b"LASF" or header[24] != 1 or header[25] > 4:
        return None
    field = {name: struct.unpack_from(layout, header, at) for name, (at, layout) in _LAS_HEADER_FIELDS.items()
             if at + struct.calcsize(layout) <= len(header)}
    minor, fmt, record_size = field["minor"][0], field["format"][0], field["record_size"][0]
    count = field["count_64" if minor >= 4 else "count"][0]
    if (field["header_size"][0] < _LAS_HEADER_SIZES[minor] or field["point_offset"][0] < field["header_size"][0]
            or fmt not in _LAS_RECORD_SIZES or record_size < _LAS_RECORD_SIZES[fmt]
            or path.stat().st_size < field["point_offset"][0] + count * record_size):
        return None
    layout = {"names": ["xyz"], "formats": [("<i4", 3)], "offsets": [0], "itemsize": record_size}
    if fmt in _LAS_RED_AT:
        layout = {**layout, "names": ["xyz", "rgb"], "formats": [("<i4", 3), ("<u2", 3)],
                  "offsets": [0, _LAS_RED_AT[fmt]]}
    records = np.fromfile(path, dtype=np.dtype(layout), count=count, offset=field["point_offset"][0])
    scales, offsets = np.array(field["scales"]), np.array(field["offsets"])
    points = np.column_stack([records["xyz"][:, k] * scales[k] + offsets[k] for k in range(3)])
    return points, _las_colours(records["rgb"]) if fmt in _LAS_RED_AT else None


def _las_colours(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 colours from a LAS file's (N, 3) red, green, blue: 16-bit values scaled to 8 bits, values
    that fit 8 bits as they are."""
    rgb = rgb.astype(np.float64)
    return (rgb / 257.0 if rgb.max(initial=0) > 255 else rgb).round().astype(np.uint8)


def _las_points(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    plain = _plain_las_points(path)
    if plain is not None:
        return plain
    import laspy

    try:
        las = laspy.read(path)
    except Exception as exc:  # noqa: BLE001 - laspy's errors for a broken or LAZ-without-backend file
        raise CloudError(f"{path} is not a readable LAS/LAZ file ({type(exc).__name__}: {exc})") from None
    points = np.column_stack([np.asarray(las.x, np.float64), np.asarray(las.y, np.float64),
                              np.asarray(las.z, np.float64)])
    colours = None
    if {"red", "green", "blue"} <= set(las.point_format.dimension_names):
        colours = _las_colours(np.column_stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)]))
    return points, colours


_READERS = {".xyz": _text_points, ".txt": _text_points, ".csv": _text_points, ".pts": _text_points,
            ".ply": _ply_points, ".las": _las_points, ".laz": _las_points}


def read_cloud(source, up: str = "z") -> PointCloud:
    """The cloud in `source` (a path with a suffix in CLOUD_SUFFIXES, or an (N, 3) array of metres) in the
    working frame. up : the source's up axis (UP_AXES; default "z")."""
    if up not in UP_AXES:
        raise CloudError(f"up axis {up!r} is unknown: allowed {', '.join(UP_AXES)}")
    colours = None
    if isinstance(source, (str, Path)):
        path = Path(source)
        suffix = path.suffix.lower()
        if suffix not in _READERS:
            raise CloudError(f"{path} is not a point cloud file: allowed suffixes {', '.join(CLOUD_SUFFIXES)}")
        if not path.is_file():
            raise CloudError(f"point cloud {path} does not exist")
        raw, colours = _READERS[suffix](path)
        name = str(path)
    else:
        raw = np.asarray(source)
        name = "array"
        if raw.dtype == object or not np.issubdtype(raw.dtype, np.number):
            raise CloudError(f"the cloud array has dtype {raw.dtype}: allowed numbers, shape (N, 3)")
        if raw.ndim != 2 or raw.shape[1] != 3:
            raise CloudError(f"the cloud array has shape {raw.shape}: allowed (N, 3)")
        raw = raw.astype(np.float64)
    finite = np.isfinite(raw).all(axis=1)
    if not finite.all():
        raise CloudError(f"{name} has {int((~finite).sum())} point(s) with NaN or infinite coordinates (first: point "
                         f"{int(np.flatnonzero(~finite)[0]) + 1}): allowed finite numbers")
    if len(raw) < MIN_POINTS:
        raise CloudError(f"{name} has {len(raw)} points: allowed at least {MIN_POINTS} for a tree")
    upright = to_z_up(raw, up)
    low, high = upright.min(axis=0), upright.max(axis=0)
    if high[2] - low[2] < MIN_HEIGHT_M:
        raise CloudError(f"{name} spans {high[2] - low[2]:.3g} m along its up axis {up!r}: allowed at least "
                         f"{MIN_HEIGHT_M} m (is --up right?)")
    offset = np.array([0.5 * (low[0] + high[0]), 0.5 * (low[1] + high[1]), low[2]])
    points = (upright - offset).astype(np.float32)
    return PointCloud(points, offset, up, UP_AXES[up].copy(), colours, name)
