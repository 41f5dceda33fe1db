"""A torch `Dataset` over a dataset's views table: one item per (tree, view), images decoded on access.

PNG bytes stay in the (memory-mapped) Arrow table until an item is asked for; torch is imported here only.
"""
from __future__ import annotations

import json
from typing import Callable, Sequence

import numpy as np

from .image_codec import decode_map
from .readers import read_columns, read_manifest, stored_float_outputs
from .schema import DatasetError, output_columns

__all__ = ["ViewsDataset"]


def _torch():
    try:
        import torch
    except ImportError:
        raise ImportError("farm.dataset.torch_dataset needs torch: pip install torch") from None
    return torch


class ViewsDataset(_torch().utils.data.Dataset):
    """Views of a finished dataset as dicts of tensors.

    path      : dataset folder or URI.
    outputs   : the outputs to decode (default: every stored one).
    with_params : add the tree's parameter dictionary (`params`, a dict) from the trees table.
    transform : optional function applied to each item dict.

    Item: `tree_id` str, `index` int, `view` int, `view_name` str, `camera` dict, and per output a tensor:
    uint8 maps as uint8 (C, H, W), float maps as float32 (C, H, W) (metres for depth maps, else [0, 1]).
    """

    def __init__(self, path: str, outputs: Sequence[str] | None = None, with_params: bool = False,
                 transform: Callable[[dict], dict] | None = None):
        stored = read_manifest(path)["job"]["render"]["outputs"]
        self.outputs = list(stored if outputs is None else outputs)
        for name in self.outputs:
            if name not in stored:
                raise DatasetError(f"output {name!r} is not in this dataset: stored {', '.join(stored)}")
        columns = ["tree_id", "index", "view", "view_name", "camera_json",
                   *output_columns(self.outputs, stored_float_outputs(path))]
        self.table = read_columns(path, "views", columns, memory_map=True)
        self.params: dict[str, dict] | None = None
        if with_params:
            trees = read_columns(path, "trees", ["tree_id", "params_json"])
            self.params = {row["tree_id"]: json.loads(row["params_json"]) for row in trees.to_pylist()
                           if row["params_json"] is not None}
        self.transform = transform

    def __len__(self) -> int:
        return self.table.num_rows

    def __getitem__(self, item: int) -> dict:
        torch = _torch()
        if not 0 <= item < len(self):
            raise IndexError(f"view {item} out of range [0, {len(self)})")
        row = self.table.slice(item, 1).to_pylist()[0]
        out = {"tree_id": row["tree_id"], "index": row["index"], "view": row["view"],
               "view_name": row["view_name"], "camera": json.loads(row["camera_json"])}
        for name in self.outputs:
            image = decode_map(row[name], row.get(f"{name}_scale"), row.get(f"{name}_offset"))
            image = image[None] if image.ndim == 2 else np.moveaxis(image, 2, 0)
            out[name] = torch.from_numpy(np.ascontiguousarray(image))
        if self.params is not None:
            out["params"] = self.params[row["tree_id"]]
        return self.transform(out) if self.transform else out
