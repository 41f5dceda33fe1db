"""Quantitative structure model outputs of a reconstructed tree: the skeleton as a PLY of vertices and edges (what
AdTree writes), the measures QSM users compare (height, DBH, crown projection, woody volume by order, lengths) and a
branch table.

In: a `Skeleton` (Z up, metres) and, for the measures read off a scan, its points. Out: PLY files (ascii or binary
little-endian) and their reader, a flat dict of measures and its one-row CSV, the branch table and its CSV. Every
sum is a bincount over node arrays, no loop over nodes.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order

from species.errors import TreefarmError, user_path
from species.lsystem.lstring_io import branch_orders
from species.meshing.ascii_numbers import fixed6_rows, int_rows
from species.skeleton import Skeleton

from .scan_measures import MIN_ARC_DEG, MIN_STEM_POINTS, crown_projection, stem_circle, trunk_at_height

__all__ = ["QsmError", "write_skeleton_ply", "read_skeleton_ply", "qsm_measures", "write_qsm_csv", "branch_table",
           "branch_columns", "write_branch_csv", "segment_volumes", "BREAST_HEIGHT_M", "PLY_FORMATS",
           "BRANCH_COLUMNS", "QSM_COLUMNS", "ORDER_VOLUME_COLUMNS"]

BREAST_HEIGHT_M = 1.3  # where DBH is measured, above the tree's base
PLY_FORMATS = {"ascii": "ascii", "binary": "binary_little_endian"}
BRANCH_COLUMNS = ("id", "parent", "order", "length_m", "base_radius_m", "volume_m3")
# Woody volume by branch order: the trunk, first and second orders, and every higher order together (fixed columns,
# so the tables of different trees line up).
ORDER_VOLUME_COLUMNS = ("volume_order_0_m3", "volume_order_1_m3", "volume_order_2_m3", "volume_order_3plus_m3")
QSM_COLUMNS = ("height_m", "scan_height_m", "dbh_m", "dbh_method", "dbh_points", "dbh_arc_deg", "dbh_rms_m",
               "skeleton_dbh_m", "dbh_note", "breast_height_m", "crown_projection_area_m2", "crown_diameter_m",
               "trunk_volume_m3", "total_volume_m3", *ORDER_VOLUME_COLUMNS, "trunk_length_m", "total_length_m",
               "branch_count", "max_order")
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_BYTE_ORDERS = {"binary_little_endian": "<", "binary_big_endian": ">"}


class QsmError(TreefarmError):
    """A skeleton file that cannot be read or written, or an output option out of range."""


# ------------------------------------------------------------------------------------------------ PLY
def write_skeleton_ply(skeleton: Skeleton, path: str | Path, offset=None, file_format: str = "binary") -> None:
    """Write `skeleton` as a PLY: `vertex` (x, y, z, radius) per node and `edge` (vertex1 = parent, vertex2 = child).

    offset : optional (3,) metres added to every position in float64 (a `PointCloud.offset`, so a georeferenced
    scan's coordinates come back); positions are then written as double, else as float. Radii are float.
    file_format : "binary" (little-endian) or "ascii" (6 decimals). Leaves are not written (a skeleton file).
    """
    if file_format not in PLY_FORMATS:
        raise QsmError(f"PLY format {file_format!r} is unknown: allowed {', '.join(PLY_FORMATS)}")
    positions = skeleton.positions
    if offset is not None:
        shift = np.asarray(offset, np.float64)
        if shift.shape != (3,) or not np.all(np.isfinite(shift)):
            raise QsmError(f"offset {np.ravel(shift).tolist()} is invalid: allowed three finite numbers (metres)")
        positions = positions.astype(np.float64) + shift
    coordinate = "double" if positions.dtype == np.float64 else "float"
    n_edges = len(skeleton) - 1
    header = "\n".join([
        "ply", f"format {PLY_FORMATS[file_format]} 1.0",
        "comment treefarm skeleton: Z up, metres; each edge runs from a parent (vertex1) to its child (vertex2)",
        f"element vertex {len(skeleton)}", *(f"property {coordinate} {axis}" for axis in "xyz"),
        "property float radius", f"element edge {n_edges}", "property int vertex1", "property int vertex2",
        "end_header", ""]).encode("ascii")
    edges = np.stack([skeleton.parent[1:], np.arange(1, len(skeleton))], axis=1).astype(np.int32)
    if file_format == "ascii":
        # fixed6_rows and int_rows start each line with "<tag><separator>": an empty tag leaves a space to drop.
        vertex_text = fixed6_rows("", np.column_stack([positions.astype(np.float64), skeleton.radius]))
        edge_text = int_rows("", edges, "  ")
        body = (b"\n" + vertex_text + edge_text).replace(b"\n ", b"\n")[1:]
    else:
        vertex = np.zeros(len(skeleton), [("x", "<" + _PLY_TYPES[coordinate]), ("y", "<" + _PLY_TYPES[coordinate]),
                                          ("z", "<" + _PLY_TYPES[coordinate]), ("radius", "<f4")])
        vertex["x"], vertex["y"], vertex["z"], vertex["radius"] = positions.T[0], positions.T[1], positions.T[2], \
            skeleton.radius
        body = vertex.tobytes() + edges.astype("<i4").tobytes()
    with user_path(path, "write"):
        Path(path).write_bytes(header + body)


def _ply_header(data: bytes, path) -> tuple[str, list[tuple[str, int, list[tuple[str, str]]]], int]:
    """(format, [(element, count, [(property, numpy type)])], offset of the body) of PLY bytes."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise QsmError(f"{path} is not a PLY file (no 'ply' magic or no 'end_header'): allowed a PLY skeleton")
    body_start = data.index(b"\n", end) + 1
    file_format, elements = None, []
    for line in data[:end].decode("ascii", errors="replace").splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            file_format = words[1]
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            if words[1] == "list":
                raise QsmError(f"{path}: element {elements[-1][0]!r} has a list property {words[-1]!r}: allowed "
                               "scalar properties only (a skeleton of vertices and edges)")
            if words[1] not in _PLY_TYPES:
                raise QsmError(f"{path}: property type {words[1]!r} is unknown: allowed {', '.join(_PLY_TYPES)}")
            elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
    if file_format not in ("ascii", *_BYTE_ORDERS):
        raise QsmError(f"{path}: PLY format {file_format!r} is unknown: allowed ascii, {', '.join(_BYTE_ORDERS)}")
    return file_format, elements, body_start


def _ply_elements(data: bytes, path) -> dict[str, dict[str, np.ndarray]]:
    """Every element of PLY bytes as {element: {property: (count,) array}}."""
    file_format, elements, offset = _ply_header(data, path)
    out: dict[str, dict[str, np.ndarray]] = {}
    if file_format == "ascii":
        lines = data[offset:].split(b"\n")
        row = 0
        for name, count, properties in elements:
            block = b" ".join(lines[row:row + count])
            values = np.array(block.split(), np.float64) if count else np.zeros(0)
            if values.size != count * len(properties):
                raise QsmError(f"{path}: element {name!r} should hold {count} rows of {len(properties)} numbers; "
                               f"found {values.size} numbers")
            table = values.reshape(count, len(properties))
            out[name] = {prop: table[:, k].astype(kind) for k, (prop, kind) in enumerate(properties)}
            row += count
        return out
    byte_order = _BYTE_ORDERS[file_format]
    for name, count, properties in elements:
        dtype = np.dtype([(prop, byte_order + kind) for prop, kind in properties])
        if offset + count * dtype.itemsize > len(data):
            raise QsmError(f"{path}: element {name!r} needs {count * dtype.itemsize} bytes; the file ends first")
        table = np.frombuffer(data, dtype, count, offset)
        out[name] = {prop: table[prop].astype(table[prop].dtype.newbyteorder("=")) for prop, _ in properties}
        offset += count * dtype.itemsize
    return out


def read_skeleton_ply(path: str | Path, offset=None) -> Skeleton:
    """The Skeleton in a PLY of `vertex` (x, y, z, radius) and `edge` (vertex1, vertex2) elements.

    A file whose edges run parent -> child with every parent listed before its child and vertex 0 as the root
    (as `write_skeleton_ply` writes) keeps its numbering; any other tree of edges (AdTree's, undirected) is
    walked breadth-first from its lowest vertex and renumbered. offset : optional (3,) metres subtracted in
    float64 before the positions become float32. Orders come from `branch_orders` (a PLY carries none).
    """
    with user_path(path, "read"):
        data = Path(path).read_bytes()
    elements = _ply_elements(data, path)
    vertex, edge = elements.get("vertex"), elements.get("edge")
    if vertex is None or edge is None or not {"x", "y", "z", "radius"} <= set(vertex) \
            or not {"vertex1", "vertex2"} <= set(edge):
        raise QsmError(f"{path} lacks a vertex element with x, y, z, radius or an edge element with vertex1, vertex2:"
                       f" found {', '.join(f'{k}({len(v)} properties)' for k, v in elements.items()) or 'nothing'}")
    positions = np.column_stack([vertex["x"], vertex["y"], vertex["z"]]).astype(np.float64)
    if offset is not None:
        positions -= np.asarray(offset, np.float64)
    radius = vertex["radius"].astype(np.float64)
    n = len(positions)
    first, second = edge["vertex1"].astype(np.int64), edge["vertex2"].astype(np.int64)
    if n == 0 or len(first) != n - 1 or (len(first) and (min(first.min(), second.min()) < 0
                                                          or max(first.max(), second.max()) >= n)):
        raise QsmError(f"{path} has {n} vertices and {len(first)} edges: allowed a tree, n - 1 edges between "
                       "vertex indices")
    parent = np.full(n, -1, np.int64)
    parent[second] = first
    ordered = bool(np.all(first < second)) and len(np.unique(second)) == n - 1 and (n == 1 or second.min() == 1)
    if not ordered:
        graph = coo_matrix((np.ones(n - 1), (first, second)), shape=(n, n)).tocsr()
        root = int(np.argmin(positions[:, 2]))
        walk, predecessor = breadth_first_order(graph, root, directed=False, return_predecessors=True)
        if len(walk) != n:
            raise QsmError(f"{path}: {n - len(walk)} of {n} vertices are not connected to the lowest one: allowed "
                           "one tree")
        new_index = np.empty(n, np.int64)
        new_index[walk] = np.arange(n)
        parent = np.where(predecessor[walk] < 0, -1, new_index[np.maximum(predecessor[walk], 0)])
        positions, radius = positions[walk], radius[walk]
    return Skeleton(positions=positions, parent=parent, radius=radius, order=branch_orders(positions, parent))


# -------------------------------------------------------------------------------------------- measures
def segment_volumes(skeleton: Skeleton) -> np.ndarray:
    """(N,) float64 m^3, the frustum pi h (r1^2 + r1 r2 + r2^2) / 3 of the edge from each node's parent to it (0 at
    the root): h the edge length, r2 the node's radius, r1 its parent's, except where the node starts a new
    branch, where r1 = min(parent's, node's) (the branch begins at its own thickness, as `build_mesh` models the
    joint, not at the thickness of the branch it grows from)."""
    radius = skeleton.radius.astype(np.float64)
    start = radius[np.maximum(skeleton.parent, 0)]
    starts = skeleton.branch_starts
    start[starts] = np.minimum(start[starts], radius[starts])
    volume = math.pi * skeleton.segment_lengths * (start ** 2 + start * radius + radius ** 2) / 3.0
    volume[0] = 0.0
    return volume


def _order_volumes(skeleton: Skeleton, volume: np.ndarray) -> dict[str, float]:
    """Woody volume per branch order, the orders from ORDER_VOLUME_COLUMNS' last on summed into it."""
    last = len(ORDER_VOLUME_COLUMNS) - 1
    sums = np.bincount(np.minimum(skeleton.order.astype(np.int64), last), volume, last + 1)
    return {name: float(v) for name, v in zip(ORDER_VOLUME_COLUMNS, sums)}


def _dbh(skeleton: Skeleton, points: np.ndarray | None, breast_height: float) -> dict:
    """The DBH keys of `qsm_measures`."""
    at = trunk_at_height(skeleton, breast_height)
    skeleton_dbh = None if at is None else float(2.0 * at[1])
    circle = None if points is None else stem_circle(points, skeleton, breast_height)
    if circle is not None:
        return {"dbh_m": 2.0 * circle.radius, "dbh_method": "circle fit", "dbh_points": circle.n_points,
                "dbh_arc_deg": round(circle.arc_deg, 1), "dbh_rms_m": circle.rms_m, "skeleton_dbh_m": skeleton_dbh,
                "dbh_note": None}
    fit_note = None if points is None else (f"too few stem points at breast height for a circle fit (at least "
                                            f"{MIN_STEM_POINTS} over {MIN_ARC_DEG:g} degrees of arc)")
    if at is None:
        trunk_top = float(skeleton.positions[skeleton.branch_paths[0], 2].max() - skeleton.positions[0, 2])
        note = f"the trunk reaches {trunk_top:.3f} m above its base, below breast height {breast_height} m"
        return {"dbh_m": None, "dbh_method": None, "dbh_points": None, "dbh_arc_deg": None, "dbh_rms_m": None,
                "skeleton_dbh_m": None, "dbh_note": note if fit_note is None else f"{fit_note}, and {note}"}
    return {"dbh_m": skeleton_dbh, "dbh_method": "skeleton radius", "dbh_points": None, "dbh_arc_deg": None,
            "dbh_rms_m": None, "skeleton_dbh_m": skeleton_dbh,
            "dbh_note": None if fit_note is None else f"{fit_note}: the skeleton's radius"}


def qsm_measures(skeleton: Skeleton, points: np.ndarray | None = None,
                 breast_height: float = BREAST_HEIGHT_M) -> dict:
    """The QSM measures of `skeleton` (and of the scan's `points` where given), JSON-able, flat, metres, square and
    cubic metres; the keys are QSM_COLUMNS, in that order.

    points : optional (N, 3) metres in the skeleton's frame (Z up, the base at node 0), the scan the skeleton was
            measured from: DBH, height and crown are then read from it.
    dbh_m : the stem's diameter where the trunk (branch 0) is `breast_height` above its base (z - z of node 0):
            `dbh_method` "circle fit" (`scan_measures.stem_circle` on the scan's stem points there, robust to a
            half-scanned stem: `dbh_points` kept, `dbh_arc_deg` of arc they cover, `dbh_rms_m` off the circle) or,
            without points or with too few, "skeleton radius" (twice the radius interpolated between the two trunk
            nodes around breast height: `skeleton_dbh_m`, given whenever the trunk reaches breast height); None when
            neither can be had, with `dbh_note` saying why (a note also says why a fit fell back).
    height_m : highest node above the base; scan_height_m : highest scan point above the base (None without points).
    crown_projection_area_m2, crown_diameter_m : the convex hull of the points' ground projection, its area and
            the diameter of its smallest enclosing circle (`scan_measures.crown_projection`; None without points).
    trunk_volume_m3, total_volume_m3 : sums of `segment_volumes` over the trunk's nodes and over all nodes
            (woody volume: bark tubes, no leaves); volume_order_0_m3 ... volume_order_3plus_m3 : by branch order.
    trunk_length_m, total_length_m : edge lengths summed over the trunk and over all nodes.
    branch_count : branches other than the trunk; max_order.
    """
    if not (isinstance(breast_height, (int, float)) and 0 < breast_height < 1e3):
        raise QsmError(f"breast_height {breast_height!r} is invalid: allowed metres in (0, 1000)")
    if points is not None:
        points = np.asarray(points, np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or not len(points):
            raise QsmError(f"points of shape {points.shape} are invalid: allowed (N, 3) metres, N >= 1")
    volume = segment_volumes(skeleton)
    on_trunk = skeleton.branch_id == 0
    base = float(skeleton.positions[0, 2])
    crown = None if points is None else crown_projection(points)
    measures = {
        "height_m": float(skeleton.positions[:, 2].max() - base),
        "scan_height_m": None if points is None else float(points[:, 2].max() - base),
        **_dbh(skeleton, points, float(breast_height)), "breast_height_m": float(breast_height),
        "crown_projection_area_m2": None if crown is None else crown.area_m2,
        "crown_diameter_m": None if crown is None else crown.diameter_m,
        "trunk_volume_m3": float(volume[on_trunk].sum()), "total_volume_m3": float(volume.sum()),
        **_order_volumes(skeleton, volume),
        "trunk_length_m": float(skeleton.segment_lengths[on_trunk].sum(dtype=np.float64)),
        "total_length_m": skeleton.total_length,
        "branch_count": skeleton.n_branches - 1, "max_order": int(skeleton.order.max()),
    }
    return {key: measures[key] for key in QSM_COLUMNS}


def write_qsm_csv(measures: dict, path: str | Path, source: str = "") -> None:
    """The tree's measures (`qsm_measures`, plus whatever keys a caller added) as a CSV of one header row and one
    row: `source` (the scan), then QSM_COLUMNS, then any other keys in their order; floats to 9 significant
    digits, a missing value empty. One row a tree, the same columns for every tree: files concatenate."""
    columns = ["source", *QSM_COLUMNS, *(key for key in measures if key not in QSM_COLUMNS)]
    row = {"source": source, **measures}
    cells = ["" if row.get(c) is None else (f"{row[c]:.9g}" if isinstance(row[c], float) else str(row[c]))
             for c in columns]
    with user_path(path, "write"):
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(columns)
            writer.writerow(cells)


def branch_columns(skeleton: Skeleton) -> dict[str, np.ndarray]:
    """One row per branch (`Skeleton.branch_paths`, the trunk first) as {column: (B,) array}, columns BRANCH_COLUMNS:

    id : branch id (`Skeleton.branch_id`); parent : the id of the branch it grows from, -1 for the trunk;
    order : its branch order; length_m : its edges summed (the edge from its junction included, so the rows
    sum to the skeleton's total length); base_radius_m : the radius of its first own node; volume_m3 : its
    `segment_volumes` summed (the rows sum to the total woody volume).
    """
    branch = skeleton.branch_id
    starts = skeleton.branch_starts
    n_branches = skeleton.n_branches
    junction = skeleton.parent[starts]
    return {
        "id": np.arange(n_branches, dtype=np.int64),
        "parent": np.where(junction >= 0, branch[np.maximum(junction, 0)], -1).astype(np.int64),
        "order": skeleton.order[starts].astype(np.int64),
        "length_m": np.bincount(branch, skeleton.segment_lengths.astype(np.float64), n_branches),
        "base_radius_m": skeleton.radius[starts].astype(np.float64),
        "volume_m3": np.bincount(branch, segment_volumes(skeleton), n_branches),
    }


def branch_table(skeleton: Skeleton):
    """`branch_columns` as a pandas DataFrame."""
    import pandas as pd  # here: pandas is for scripts; the command line writes the table without it (start-up time)

    return pd.DataFrame(branch_columns(skeleton), columns=list(BRANCH_COLUMNS))


def write_branch_csv(skeleton: Skeleton, path: str | Path) -> None:
    """`branch_columns` as CSV with a header row, floats to 9 significant digits."""
    columns = branch_columns(skeleton)
    text = [",".join(BRANCH_COLUMNS)]
    integers = np.column_stack([columns[c] for c in ("id", "parent", "order")])
    floats = np.column_stack([columns[c] for c in ("length_m", "base_radius_m", "volume_m3")])
    text += [f"{i},{p},{o},{a:.9g},{b:.9g},{c:.9g}" for (i, p, o), (a, b, c) in zip(integers.tolist(), floats.tolist())]
    with user_path(path, "write"):
        Path(path).write_text("\n".join(text) + "\n")
