"""`farm inspect DIR`: a per-species summary table of a dataset and a contact sheet PNG of its first trees.

The contact sheet has one row per tree (first view) and one column per stored output.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from species.errors import user_path

from farm.commands import check_flag_int

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("inspect", help="summary table and contact sheet PNG of a dataset",
                                   description=__doc__)
    parser.add_argument("dir", help="dataset folder or URI")
    parser.add_argument("--png", help="contact sheet path (default: DIR/contact_sheet.png, or ./ for a URI)")
    parser.add_argument("--rows", type=int, default=8, help="trees on the contact sheet (default 8)")
    parser.set_defaults(run=run)


def summary_table(path: str) -> str:
    """Per species: trees, failures, mean height and crown radius (m), nodes, leaves, triangles, views."""
    import duckdb

    from farm.dataset import DatasetError, duckdb_connect

    connection = duckdb_connect(path)
    try:
        rows = connection.execute("""
            SELECT species, count(*) AS trees, count(error) AS failed,
                   avg(height) AS height, avg(crown_radius) AS crown, avg(n_nodes) AS nodes,
                   avg(n_leaves) AS leaves, avg(bark_triangles + leaf_triangles) AS triangles, sum(n_views) AS views
            FROM trees GROUP BY species ORDER BY species""").fetchall()
    except (duckdb.InvalidInputException, duckdb.IOException) as exc:  # DuckDB's message names the part file
        reason = " ".join(str(exc).split())
        raise DatasetError(f"{path}: a part file cannot be read ({reason}): `farm validate {path}` names the "
                           f"damaged files") from None
    # Wide enough for the longest species name and a gap (some preset names run past the usual 24).
    name_width = max([24, *(len(row[0]) + 2 for row in rows)])
    lines = [f"{'species':<{name_width}}{'trees':>6}{'failed':>7}{'height m':>10}{'crown m':>9}{'nodes':>8}"
             f"{'leaves':>8}{'triangles':>11}{'views':>7}"]
    for name, trees, failed, height, crown, nodes, leaves, triangles, views in rows:
        def number(value, width: int, decimals: int) -> str:  # "-" where no tree of the species has one
            return f"{value:>{width}.{decimals}f}" if value is not None else f"{'-':>{width}}"
        lines.append(f"{name:<{name_width}}{trees:>6}{failed:>7}{number(height, 10, 2)}{number(crown, 9, 2)}"
                     f"{number(nodes, 8, 0)}{number(leaves, 8, 0)}{number(triangles, 11, 0)}{int(views or 0):>7}")
    return "\n".join(lines)


def contact_rows(path: str, n_rows: int) -> list:
    """Contact-sheet rows: (tree id and species, [(output, decoded image of the tree's first view), ...])."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from farm.dataset import open as open_table, read_manifest
    from farm.dataset.image_codec import decode_map
    from renderers import LABEL_MAPS, METRIC_MAPS, viewable

    outputs = read_manifest(path)["job"]["render"]["outputs"]
    trees = open_table(path, "trees").to_table(columns=["tree_id", "species", "error"])
    good = trees.filter(pc.is_null(trees["error"])).slice(0, n_rows).to_pylist()
    species = {row["tree_id"]: row["species"] for row in good}
    views = open_table(path, "views").to_table(filter=pc.field("view") == 0)
    views = views.filter(pc.is_in(views["tree_id"], value_set=pa.array(list(species), pa.string()))).to_pylist()
    rows = []
    for view in sorted(views, key=lambda v: v["index"]):
        cells = []
        for name in outputs:
            # A float map's row holds its scale and offset; an 8-bit map's has neither (None).
            image = decode_map(view[name], view.get(f"{name}_scale"), view.get(f"{name}_offset"))
            if name in METRIC_MAPS and image.max() > 0:  # metres to [0, 1] for display
                image = image / image.max()
            elif name in LABEL_MAPS:  # small class labels (0, 1, 2, ...) spread over the grey range
                image = (image * (255 // max(1, int(image.max())))).astype(np.uint8)
            else:  # a silhouette map's background black, not its far depth (red)
                image = viewable(name, image)
            cells.append((name, image))
        rows.append((f"{view['index']} {species[view['tree_id']]}", cells))
    return rows


def run(args: argparse.Namespace) -> int:
    from renderers import write_contact_sheet

    from farm.dataset.storage import Location

    check_flag_int("--rows", args.rows, 1)
    print(summary_table(args.dir))
    rows = contact_rows(args.dir, args.rows)
    if not rows:
        print("no successful trees with views: no contact sheet")
        return 0
    location = Location.resolve(args.dir)
    png = Path(args.png) if args.png else (Path(location.root) if location.is_local else Path(".")) / "contact_sheet.png"
    with user_path(png, "write"):
        write_contact_sheet(png, rows)
    print(f"contact sheet: {png}")
    return 0
