"""What the review server reads from a dataset: an in-memory index of trees and views over the Parquet shards.

At start the light columns (ids, species, stats) are read once and each tree is mapped to its (part, row group,
row); GLBs, skeletons and images are read from that one row group on demand. Nothing is unpacked to disk.
"""
from __future__ import annotations

import json
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from farm.dataset import Location, open_part, output_columns, read_manifest, read_part, stored_float_outputs
from farm.dataset.image_codec import decode_map, encode_map
from renderers import LABEL_MAPS, METRIC_MAPS, OUTPUTS
from renderers.contact_sheet import without_background
from species.errors import TreefarmError

from .qa import QA_VERSION, TREE_COLUMNS, QaFlags, ink_flags, tree_flags

__all__ = ["DatasetIndex", "NotFound", "TreeRef", "LIST_COLUMNS", "viewable_png"]

# Columns the tree list shows and filters on (everything but the heavy arrays and GLB bytes).
LIST_COLUMNS = ["tree_id", "index", "shard", "species", "generator", "seed", "height", "crown_radius", "n_nodes",
                "n_branches", "n_leaves", "bark_triangles", "leaf_triangles", "n_vertices", "n_views", "error"]
# Row groups kept decoded (GLB columns are the big ones: a few MiB per shard).
_CACHE_ENTRIES = 8


class NotFound(TreefarmError, KeyError):
    """A tree, view, output or batch that the dataset does not have (a KeyError too: a lookup that missed)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "not found"


@dataclass(frozen=True)
class TreeRef:
    """Where one row lives: the part file (relative to the dataset), its row group, and the row in the group."""

    part: str
    row_group: int
    row: int


class _RowGroupCache:
    """A small LRU of decoded (part, row group, columns) tables, shared by the server's threads."""

    def __init__(self, location: Location):
        self.location = location
        self._tables: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def read(self, ref: TreeRef, columns: tuple[str, ...]):
        key = (ref.part, ref.row_group, columns)
        with self._lock:
            if key in self._tables:
                self._tables.move_to_end(key)
                return self._tables[key]
        with open_part(self.location, self.location.path(ref.part)) as parquet:
            table = parquet.read_row_group(ref.row_group, columns=list(columns))
        with self._lock:
            self._tables[key] = table
            while len(self._tables) > _CACHE_ENTRIES:
                self._tables.popitem(last=False)
        return table


def _row_refs(location: Location, part: str, columns: list[str]):
    """The light columns of one part file and a TreeRef for each of its rows."""
    import pyarrow as pa

    with open_part(location, location.path(part)) as parquet:
        groups = [parquet.read_row_group(g, columns=columns) for g in range(parquet.num_row_groups)]
    refs = [TreeRef(part, g, r) for g, table in enumerate(groups) for r in range(table.num_rows)]
    return (pa.concat_tables(groups) if groups else None), refs


class DatasetIndex:
    """A finished dataset opened for review: manifest, tree list (pandas), view lists, batches, readers."""

    def __init__(self, path: str):
        import pandas as pd
        import pyarrow as pa

        self.location = Location.resolve(path)
        self.manifest = read_manifest(self.location)
        self.outputs: list[str] = list(self.manifest["job"]["render"]["outputs"])
        self.float_outputs = stored_float_outputs(self.location)
        self.sketch_output = next((o for o in self.outputs if o.startswith("sketch")), None)
        self.name = self.manifest["job"]["name"]
        self._cache = _RowGroupCache(self.location)
        tables, self._tree_refs, self.batches = [], {}, []
        self._views: dict[str, list[tuple[int, str, TreeRef]]] = {}
        for shard in self.manifest["shards"]:
            table, refs = _row_refs(self.location, shard["trees"]["path"], LIST_COLUMNS)
            if table is None:
                continue
            tables.append(table)
            self._tree_refs.update(zip(table["tree_id"].to_pylist(), refs))
            views, view_refs = _row_refs(self.location, shard["views"]["path"], ["tree_id", "view", "view_name"])
            if views is not None:
                for tree_id, view, name, ref in zip(views["tree_id"].to_pylist(), views["view"].to_pylist(),
                                                    views["view_name"].to_pylist(), view_refs):
                    self._views.setdefault(tree_id, []).append((view, name, ref))
            self.batches.append({"id": f"part-{shard['shard']:05d}", "shard": shard["shard"],
                                 "trees": table.num_rows,
                                 # QA flags are cached under this: new bytes or new checks, new flags.
                                 "qa_key": f"{shard['trees']['sha256']}:{shard['views']['sha256']}:{QA_VERSION}"})
        self.trees = (pa.concat_tables(tables).to_pandas() if tables else
                      pd.DataFrame({name: [] for name in LIST_COLUMNS}))
        self.trees["batch"] = [f"part-{shard:05d}" for shard in self.trees["shard"]]
        self.trees = self.trees.set_index("tree_id", drop=False)

    # ------------------------------------------------------------------ lookups
    def ref(self, tree_id: str) -> TreeRef:
        if tree_id not in self._tree_refs:
            raise NotFound(f"tree {tree_id!r} is not in dataset {self.name!r}")
        return self._tree_refs[tree_id]

    def batch(self, batch_id: str) -> dict:
        for batch in self.batches:
            if batch["id"] == batch_id:
                return batch
        raise NotFound(f"batch {batch_id!r} is not in dataset {self.name!r}; batches: "
                       f"{', '.join(b['id'] for b in self.batches[:5])}{' ...' if len(self.batches) > 5 else ''}")

    def views(self, tree_id: str) -> list[dict]:
        self.ref(tree_id)
        return [{"view": view, "name": name} for view, name, _ in sorted(self._views.get(tree_id, []))]

    def _cell(self, ref: TreeRef, column: str):
        return self._cache.read(ref, (column,)).column(0)[ref.row].as_py()

    def glb(self, tree_id: str) -> bytes:
        data = self._cell(self.ref(tree_id), "glb")
        if data is None:
            raise NotFound(f"tree {tree_id!r} has no stored GLB (the job ran with store_glb: false, "
                           f"or the build failed)")
        return data

    def params(self, tree_id: str) -> dict | None:
        text = self._cell(self.ref(tree_id), "params_json")
        return json.loads(text) if text is not None else None

    def skeleton(self, tree_id: str) -> dict:
        """Node positions (N*3 floats, m, Z up), parents (N ints) and branch orders (N ints) as JSON lists."""
        ref = self.ref(tree_id)
        table = self._cache.read(ref, ("positions", "parent", "order"))
        return {name: table[name][ref.row].as_py() or [] for name in ("positions", "parent", "order")}

    def view_image(self, tree_id: str, view: int, output: str) -> bytes:
        """One stored map of one view as a PNG a browser shows (8-bit; float maps rescaled for the eye)."""
        if output not in self.outputs:
            raise NotFound(f"output {output!r} is not stored in this dataset; stored: {', '.join(self.outputs)}")
        matches = [ref for number, _, ref in self._views.get(tree_id, []) if number == view]
        if not matches:
            self.ref(tree_id)
            raise NotFound(f"tree {tree_id!r} has no view {view}")
        ref = matches[0]
        columns = tuple(output_columns([output], self.float_outputs))
        row = self._cache.read(ref, columns).slice(ref.row, 1).to_pylist()[0]
        return viewable_png(output, row[output], row.get(f"{output}_scale"), row.get(f"{output}_offset"))

    # ------------------------------------------------------------------ QA
    def compute_qa(self, batch: dict) -> QaFlags:
        """Flags of one batch (shard): tree checks from its trees part, ink checks from its sketches."""
        shard = next(s for s in self.manifest["shards"] if f"part-{s['shard']:05d}" == batch["id"])
        trees_file, views_file = (self.location.path(shard[table]["path"]) for table in ("trees", "views"))
        flags = tree_flags(read_part(self.location, trees_file, TREE_COLUMNS))
        if self.sketch_output is not None:
            views = read_part(self.location, views_file, ["tree_id", self.sketch_output])
            flags = flags + ink_flags(views["tree_id"].to_pylist(), views[self.sketch_output].to_pylist())
        return flags


def viewable_png(output: str, png: bytes, scale: float | None, offset: float | None) -> bytes:
    """A stored map as an 8-bit PNG: depth near = bright on black; [0, 1] maps with 1 = far inverted; labels spread.
    `scale` and `offset` are a float map's (None for an 8-bit map)."""
    if png is None:
        raise NotFound(f"output {output!r} is empty for this view")
    if scale is None and output not in LABEL_MAPS:
        return png
    image = decode_map(png, scale, offset)
    if output in LABEL_MAPS:
        shown = image.astype(np.float64) * (255 // max(1, int(image.max())))
    elif output in METRIC_MAPS:
        foreground = image > 0
        shown = np.zeros(image.shape, np.float64)
        if foreground.any():
            near, far = float(image[foreground].min()), float(image[foreground].max())
            shown[foreground] = 255.0 - 200.0 * (image[foreground] - near) / max(far - near, 1e-9)
    elif output in OUTPUTS and OUTPUTS[output].mask_channel is not None:  # black outside the tree, not red
        shown = without_background(output, image).astype(np.float64) * 255.0
    else:  # depth01, trunk_depth: 1 means far / background
        shown = (1.0 - image.astype(np.float64)) * 255.0
    return encode_map(output, np.clip(np.rint(shown), 0, 255).astype(np.uint8))[0]
