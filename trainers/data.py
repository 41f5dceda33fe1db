"""Training data over one or several dataset folders: checks, the split by tree, reviewer rejections, loaders.

In: a task (`trainers.tasks`) and dataset folders made by its job spec. Out: `TrainingData` (usable trees, keyed
by (spec_digest, tree_id)), a `Split` (JSON, reapplicable), a torch `TaskDataset` decoding PNGs lazily with
seeded augmentation, and `to_ray_dataset` giving the same records as a `ray.data.Dataset` for Ray Train.

Decisions:
- Split: sha256 of "spec_digest/tree_id" as a number in [0, 1) against cumulative fractions (0.8 / 0.1 / 0.1):
  the same tree lands in the same set in every run, whatever other folders are given; all views of a tree go
  together. A frozen split (`TrainingData.split(frozen=...)`, what a retrain passes: the champion's) keeps each of
  its trees where it was and puts every tree it does not know into train, so the held-out sets stay exactly the
  trees the champion was measured on; its trees no longer in the data (or since rejected) are left out and counted.
- Rejections: a tree is left out when a reviewer's latest verdict on it is "reject" (any one reviewer suffices),
  read from DIR/reviews.sqlite (read-only) and DIR/reviews/*.parquet (`farm review export`), the later verdict of
  each (tree, reviewer) winning. "flag" and "approve" keep the tree.
- Records: `input` float32 (C, S, S) through `trainers.preprocess.prepare` (crop to the drawing, ink on 0 paper);
  sketchnet adds `params_json` (str) and `species` (str); pix2pix and segment add `target` (C, S, S) and `mask`
  (1, S, S) float32 from their module's `targets_from_views`, cut with the input's crop (nearest, background
  filled).
- Augmentation (training only), drawn from numpy.random.default_rng([seed, epoch, index]) in a fixed order:
  sketchnet's hand style (p = 0.5), one affine jitter (rotation +-3 deg, scale +-5 %, shift +-3 %) applied to the
  input, target and mask alike, stroke width (thinner, unchanged, thicker by 1 px, p = 1/3 each; thinning never
  removes a stroke) and line dropout (0-3 short pieces of stroke erased) on the input only. A segment task's
  photos take `trainers.segment.augment_photo` instead (mirror, a wider affine, colour jitter).
"""
from __future__ import annotations

import hashlib
import json
import sqlite3
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Callable, Iterable, Sequence

import cv2
import numpy as np
import torch

from farm.dataset import parse_format_json, read_columns, read_format_json, read_part
from farm.dataset.storage import Location
from farm.dataset.torch_dataset import ViewsDataset

from . import pix2pix, segment
from .preprocess import apply_crop, prepare
from .tasks import Task, TrainingDataError, get_task

__all__ = ["PARTS", "DEFAULT_FRACTIONS", "REVIEWS_DB", "REVIEWS_FOLDER", "REJECT", "Key", "Split", "Source",
           "TrainingData", "TaskDataset", "open_data", "rejected_trees", "split_part", "augment", "to_ray_dataset"]

Key = tuple[str, str]  # (spec_digest, tree_id)
PARTS = ("train", "val", "test")
DEFAULT_FRACTIONS = (0.8, 0.1, 0.1)
_SPLIT_FORMAT = "treefarm-split"
_SPLIT_VERSION = 1
_SPLIT_RULE = "sha256(spec_digest + '/' + tree_id)[:8] / 2**64 against cumulative fractions"
_SPLIT_HINT = "allowed a split `Split.save` wrote (split.json in a training run folder)"

# What `farm review` stores (farm/review/store.py, farm/review/export.py), read here without importing the review
# package: the SQLite file beside the dataset and its table, and the exported Parquet parts.
REVIEWS_DB = "reviews.sqlite"
REVIEWS_FOLDER = "reviews"
REJECT = "reject"
_VERDICTS_SQL = "SELECT tree_id, reviewer, verdict, time_ms FROM verdicts"

# Background value per channel of each target map (what a view shows where there is no tree), filled in where a
# crop or a jitter reaches past the rendered image.
TARGET_BACKGROUND = {"silhouette_envelope": (1.0, 0.0, 0.0), "trunk_depth": (1.0,), "photo_mask": (0.0,)}

# Augmentation ranges (module docstring).
JITTER_ROTATION_DEG = 3.0
JITTER_SCALE = 0.05
JITTER_SHIFT = 0.03
HAND_STYLE_P = 0.5
DROPOUT_MAX_PIECES = 3
DROPOUT_RADIUS_PX = (2.0, 5.0)  # at 256 px, scaled with the size


# ---------------------------------------------------------------------------------------------- split
def split_part(key: Key, fractions: Sequence[float] = DEFAULT_FRACTIONS) -> str:
    """The part ("train", "val" or "test") a tree's key hashes into under `fractions`."""
    digest = hashlib.sha256(f"{key[0]}/{key[1]}".encode()).digest()
    u = int.from_bytes(digest[:8], "big") / 2.0**64
    bounds = np.cumsum(fractions)
    return PARTS[min(int(np.searchsorted(bounds, u, side="right")), len(PARTS) - 1)]


def _check_fractions(fractions) -> tuple[float, float, float]:
    try:
        values = tuple(float(f) for f in fractions)
    except (TypeError, ValueError):
        values = ()
    if len(values) != 3 or min(values, default=-1) < 0 or abs(sum(values) - 1.0) > 1e-6 or values[0] <= 0:
        raise TrainingDataError(f"split fractions {fractions!r} are invalid: allowed three numbers >= 0 "
                                f"(train > 0, val, test) summing to 1")
    return values


@dataclass(frozen=True)
class Split:
    """Trees by part: `parts[name]` is a sorted tuple of (spec_digest, tree_id) keys; `fractions` of the rule."""

    fractions: tuple[float, float, float]
    parts: dict[str, tuple[Key, ...]]

    @classmethod
    def by_hash(cls, keys: Iterable[Key], fractions: Sequence[float] = DEFAULT_FRACTIONS) -> "Split":
        """Each key in the part its hash gives (`split_part`)."""
        fractions = _check_fractions(fractions)
        grouped: dict[str, list[Key]] = {part: [] for part in PARTS}
        for key in set(keys):
            grouped[split_part(key, fractions)].append(key)
        return cls(fractions, {part: tuple(sorted(grouped[part])) for part in PARTS})

    def part_of(self, key: Key) -> str | None:
        """The part holding `key`, or None."""
        for part in PARTS:
            if key in self._sets[part]:
                return part
        return None

    @cached_property
    def _sets(self) -> dict[str, frozenset]:
        return {part: frozenset(self.parts[part]) for part in PARTS}

    def reapply(self, keys: Iterable[Key]) -> "Split":
        """This split over `keys`: its own trees keep their part, new trees go to train, its trees that are not in
        `keys` are dropped (the frozen held-out split of a retrain)."""
        keys = set(keys)
        grouped = {part: [k for k in self.parts[part] if k in keys] for part in PARTS}
        known = set().union(*self._sets.values())
        grouped["train"] += [k for k in keys if k not in known]
        return Split(self.fractions, {part: tuple(sorted(grouped[part])) for part in PARTS})

    def to_json(self) -> str:
        return json.dumps({"format": _SPLIT_FORMAT, "version": _SPLIT_VERSION, "rule": _SPLIT_RULE,
                           "fractions": list(self.fractions),
                           **{part: [list(k) for k in self.parts[part]] for part in PARTS}}, indent=1)

    @classmethod
    def from_json(cls, text: str, source: str = "split") -> "Split":
        """A split from `to_json` text; TrainingDataError (naming `source`) for anything else."""
        content = parse_format_json(text, _SPLIT_FORMAT, source=source, hint=_SPLIT_HINT, error=TrainingDataError)
        return cls._from_content(content, source)

    @classmethod
    def _from_content(cls, content: dict, source: str) -> "Split":
        if content.get("version") != _SPLIT_VERSION:
            raise TrainingDataError(f"{source} has split version {content.get('version')!r}: allowed "
                                    f"{_SPLIT_VERSION}")
        fractions = _check_fractions(content.get("fractions"))
        parts, seen = {}, set()
        for part in PARTS:
            entries = content.get(part)
            if not isinstance(entries, list) or not all(
                    isinstance(e, list) and len(e) == 2 and all(isinstance(s, str) for s in e) for e in entries):
                raise TrainingDataError(f"{source}: {part!r} must be a list of [spec_digest, tree_id] pairs")
            keys = tuple(sorted((e[0], e[1]) for e in entries))
            clash = seen.intersection(keys)
            if clash:
                raise TrainingDataError(f"{source}: tree {sorted(clash)[0]} is in more than one part")
            seen.update(keys)
            parts[part] = keys
        return cls(fractions, parts)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_json())

    @classmethod
    def load(cls, path: str | Path) -> "Split":
        path = Path(path)
        return cls._from_content(read_format_json(Location.resolve(str(path.parent)), path.name, _SPLIT_FORMAT,
                                                  hint=_SPLIT_HINT, error=TrainingDataError), str(path))


# ---------------------------------------------------------------------------------------------- reviews
def _sqlite_verdicts(location: Location) -> list[tuple[str, str, str, int]]:
    if not location.is_local or not location.exists(REVIEWS_DB):
        return []
    uri = Path(location.path(REVIEWS_DB)).as_uri() + "?mode=ro"
    try:
        connection = sqlite3.connect(uri, uri=True)
        try:
            return [tuple(row) for row in connection.execute(_VERDICTS_SQL).fetchall()]
        finally:
            connection.close()
    except sqlite3.Error as exc:
        raise TrainingDataError(f"cannot read reviewer verdicts from {location.path(REVIEWS_DB)} ({exc}): "
                                f"fix or move that file") from None


def _parquet_verdicts(location: Location) -> list[tuple[str, str, str, int]]:
    rows = []
    for name in location.list(REVIEWS_FOLDER):
        if not name.endswith(".parquet") or name.startswith((".", "_")):
            continue
        table = read_part(location, location.path(f"{REVIEWS_FOLDER}/{name}"),
                          ["tree_id", "reviewer", "verdict", "time"])
        times = table.column("time").cast("int64").to_pylist()
        rows += list(zip(table.column("tree_id").to_pylist(), table.column("reviewer").to_pylist(),
                         table.column("verdict").to_pylist(), times))
    return rows


def rejected_trees(path: str) -> frozenset[str]:
    """Tree ids of the dataset at `path` whose latest verdict by some reviewer is "reject" (module docstring)."""
    location = Location.resolve(str(path))
    latest: dict[tuple[str, str], tuple[int, str]] = {}
    for tree_id, reviewer, verdict, time_ms in _parquet_verdicts(location) + _sqlite_verdicts(location):
        stamp = int(time_ms) if time_ms is not None else -1
        if (tree_id, reviewer) not in latest or stamp >= latest[(tree_id, reviewer)][0]:
            latest[(tree_id, reviewer)] = (stamp, verdict)
    return frozenset(tree_id for (tree_id, _), (_, verdict) in latest.items() if verdict == REJECT)


# ---------------------------------------------------------------------------------------------- sources
@dataclass(frozen=True, eq=False)
class Source:
    """One checked dataset folder.

    path        : the folder or URI as given.
    spec_digest : its manifest's spec digest (first half of every key).
    trees       : tree_id -> (species, params_json) of the usable trees (not failed, not rejected).
    view_trees  : (V,) tree_id of each views-table row, part-file order (the row order of ViewsDataset).
    rejected    : tree ids left out by a reviewer's rejection.  failed : number of trees that failed to build.
    """

    path: str
    spec_digest: str
    trees: dict[str, tuple[str, str]]
    view_trees: np.ndarray
    rejected: frozenset[str]
    failed: int

    @property
    def keys(self) -> list[Key]:
        return [(self.spec_digest, tree_id) for tree_id in sorted(self.trees)]


def _open_source(task: Task, path: str) -> Source:
    manifest = task.check_dataset(path)
    trees = read_columns(path, "trees", ["tree_id", "species", "params_json", "error"]).to_pylist()
    views = read_columns(path, "views", ["tree_id"]).column("tree_id").to_numpy(zero_copy_only=False)
    rejected = rejected_trees(path) & {t["tree_id"] for t in trees}
    usable = {t["tree_id"]: (t["species"], t["params_json"]) for t in trees
              if t["error"] is None and t["params_json"] is not None and t["tree_id"] not in rejected}
    failed = sum(t["error"] is not None for t in trees)
    return Source(str(path), manifest["spec_digest"], usable, views.astype(str), frozenset(rejected), failed)


@dataclass(frozen=True, eq=False)
class TrainingData:
    """The usable trees of one task over several dataset folders (`open_data`)."""

    task: Task
    sources: tuple[Source, ...]

    @property
    def keys(self) -> list[Key]:
        return [key for source in self.sources for key in source.keys]

    @property
    def rejected(self) -> int:
        """Trees left out because a reviewer rejected them, over every folder."""
        return sum(len(source.rejected) for source in self.sources)

    @property
    def paths(self) -> list[str]:
        return [source.path for source in self.sources]

    def params_of(self, key: Key) -> dict:
        """The parameter dictionary of tree `key`, with its species under `species`."""
        digest, tree_id = key
        for source in self.sources:
            if source.spec_digest == digest and tree_id in source.trees:
                species, params_json = source.trees[tree_id]
                return {**json.loads(params_json), "species": species}
        raise TrainingDataError(f"tree {tree_id} (spec digest {digest[:12]}) is not in these datasets")

    def split(self, fractions: Sequence[float] = DEFAULT_FRACTIONS, frozen: Split | None = None) -> Split:
        """The split of the usable trees: by hash, or `frozen` reapplied (its trees keep their part, new ones go to
        train; see the module docstring)."""
        if frozen is not None:
            return frozen.reapply(self.keys)
        return Split.by_hash(self.keys, fractions)

    def summary(self, split: Split, frozen: Split | None = None) -> dict:
        """What the model records about its data: trees and views per part, rejected and failed trees, per folder
        digest and counts, and (with the frozen split it was reapplied from) its trees no longer in the data."""
        views = {part: 0 for part in PARTS}
        for source in self.sources:
            names, counts = np.unique(source.view_trees, return_counts=True)
            for name, count in zip(names, counts):
                part = split.part_of((source.spec_digest, str(name)))
                if part is not None:
                    views[part] += int(count)
        out = {"trees": {part: len(split.parts[part]) for part in PARTS}, "views": views,
               "rejected": self.rejected, "failed": sum(source.failed for source in self.sources),
               "fractions": list(split.fractions),
               "sources": [{"path": s.path, "spec_digest": s.spec_digest, "trees": len(s.trees),
                            "rejected": len(s.rejected), "failed": s.failed} for s in self.sources]}
        if frozen is not None:
            present = set(self.keys)
            out["frozen_missing"] = sum(k not in present for part in PARTS for k in frozen.parts[part])
        return out


def open_data(task: str | Task, paths: str | Sequence[str]) -> TrainingData:
    """Check and open the dataset folders for `task`; TrainingDataError when one is unfit, or when two folders
    hold the same trees (same spec digest and tree id: the same job given twice)."""
    task = get_task(task)
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    if not paths:
        raise TrainingDataError(f"no training data folder given for task {task.name}: pass --data DIR [DIR...]")
    sources, owner = [], {}
    for path in paths:
        source = _open_source(task, str(path))
        for key in source.keys:
            if key in owner:
                raise TrainingDataError(f"{path} and {owner[key]} hold the same tree {key[1]} of the same job "
                                        f"(spec digest {key[0][:12]}): give each dataset once")
            owner[key] = str(path)
        sources.append(source)
    if not owner:
        raise TrainingDataError(f"the folders {', '.join(map(str, paths))} hold no usable tree for task "
                                f"{task.name} (all failed or rejected)")
    return TrainingData(task, tuple(sources))


# ---------------------------------------------------------------------------------------------- augmentation
def _affine(rng: np.random.Generator, size: int) -> np.ndarray:
    """(2, 3) float64 pixel affine: rotation and scale about the centre, then a shift."""
    angle = rng.uniform(-JITTER_ROTATION_DEG, JITTER_ROTATION_DEG)
    scale = 1.0 + rng.uniform(-JITTER_SCALE, JITTER_SCALE)
    shift = rng.uniform(-JITTER_SHIFT, JITTER_SHIFT, 2) * size
    matrix = cv2.getRotationMatrix2D(((size - 1) / 2.0, (size - 1) / 2.0), angle, scale)
    matrix[:, 2] += shift
    return matrix


def _warp(image: np.ndarray, matrix: np.ndarray, fill: Sequence[float], interpolation: int) -> np.ndarray:
    """(C, S, S) float32 warped by a (2, 3) affine, `fill` per channel outside (C <= 4)."""
    c, h, w = image.shape
    hwc = np.ascontiguousarray(np.moveaxis(image, 0, 2))
    border = tuple(float(v) for v in fill) + (0.0,) * (4 - len(fill))
    out = cv2.warpAffine(hwc, matrix, (w, h), flags=interpolation, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=border)
    return np.ascontiguousarray(np.moveaxis(out.reshape(h, w, c), 2, 0), np.float32)


_CROSS = ((0, 0), (-1, 0), (1, 0), (0, -1), (0, 1))


def _pick_neighbour(ink: np.ndarray, strongest: bool) -> np.ndarray:
    """(C, H, W): each pixel takes the whole ink vector of its strongest (or weakest) 4-neighbour or itself, so
    colour strokes keep their colours where they grow or shrink."""
    c, h, w = ink.shape
    padded = np.pad(ink, ((0, 0), (1, 1), (1, 1)))
    shifted = np.stack([padded[:, 1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy, dx in _CROSS])  # (5, C, H, W)
    strength = shifted.max(axis=1)  # (5, H, W)
    choice = strength.argmax(axis=0) if strongest else strength.argmin(axis=0)
    return np.take_along_axis(shifted, choice[None, None], axis=0)[0]


def _stroke_width(ink: np.ndarray, change: int) -> np.ndarray:
    """Strokes 1 px thicker (change 1), thinner (-1; a pixel whose whole neighbourhood would lose its ink keeps
    it, so 1-2 px lines survive) or as they are (0)."""
    if change > 0:
        return _pick_neighbour(ink, strongest=True)
    if change < 0:
        thinner = _pick_neighbour(ink, strongest=False)
        near_ink = cv2.dilate((thinner.max(axis=0) >= 0.5).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        lost = (ink.max(axis=0) >= 0.5) & ~near_ink
        return np.where(lost[None], ink, thinner)
    return ink


def _drop_lines(ink: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Erase 0-DROPOUT_MAX_PIECES discs centred on stroke pixels (short gaps, as a pen lifting)."""
    pieces = int(rng.integers(0, DROPOUT_MAX_PIECES + 1))
    inked = np.flatnonzero(ink.max(axis=0).ravel() >= 0.5)
    if pieces == 0 or len(inked) == 0:
        return ink
    h, w = ink.shape[1:]
    centres = rng.choice(inked, size=pieces)
    radii = rng.uniform(*DROPOUT_RADIUS_PX, pieces) * h / 256.0
    cy, cx = np.divmod(centres, w)
    rows, cols = np.arange(h)[None, :, None], np.arange(w)[None, None, :]
    erase = (((rows - cy[:, None, None]) ** 2 + (cols - cx[:, None, None]) ** 2)
             < (radii ** 2)[:, None, None]).any(axis=0)
    return np.where(erase[None], 0.0, ink).astype(np.float32)


def augment(inputs: np.ndarray, rng: np.random.Generator, targets: Sequence[tuple[np.ndarray, Sequence[float]]] = ()
            ) -> tuple[np.ndarray, list[np.ndarray]]:
    """One draw of the training augmentation (after the style choice): the input (C, S, S) float32 ink on 0 paper
    and each (target (C, S, S), background per channel) warped by the same affine jitter (targets nearest, so
    depth and mask values stay exact); stroke width and line dropout on the input only. Returns (input, targets).
    """
    size = inputs.shape[-1]
    matrix = _affine(rng, size)
    x = _warp(inputs, matrix, (0.0,) * inputs.shape[0], cv2.INTER_LINEAR)
    warped = [_warp(t, matrix, fill, cv2.INTER_NEAREST) for t, fill in targets]
    x = _stroke_width(x, int(rng.integers(-1, 2)))
    x = _drop_lines(x, rng)
    return np.clip(x, 0.0, 1.0).astype(np.float32), warped


# ---------------------------------------------------------------------------------------------- datasets
def _hwc(array) -> np.ndarray:
    """(C, H, W) tensor or array as (H, W) or (H, W, C) numpy."""
    array = array.numpy() if isinstance(array, torch.Tensor) else np.asarray(array)
    return array[0] if array.shape[0] == 1 else np.moveaxis(array, 0, 2)


class TaskDataset(torch.utils.data.Dataset):
    """The views of one part of a split, across folders, as training records (module docstring: Records).

    data : TrainingData.  split : Split.  part : "train", "val" or "test".
    augment : apply the seeded augmentation (training); off, every record is the plain preprocessed view.
    seed, epoch : the augmentation's generator is default_rng([seed, epoch, index]); `set_epoch` moves epochs.
    Items are dicts: `input` torch float32 (C, S, S), the task's targets (tensors, or str for sketchnet),
    `tree_id` str, `view` int, `spec_digest` str, `style` (the input output used). `record(i)` gives numpy.
    Pickles without its opened tables (DataLoader workers, Ray tasks reopen them).
    """

    def __init__(self, data: TrainingData, split: Split, part: str = "train", augment: bool = False,
                 seed: int = 0, epoch: int = 0):
        if part not in PARTS:
            raise TrainingDataError(f"split part {part!r} is unknown: allowed {', '.join(PARTS)}")
        self.data, self.part, self.augment, self.seed, self.epoch = data, part, bool(augment), int(seed), int(epoch)
        wanted = set(split.parts[part])
        rows = []
        for s, source in enumerate(data.sources):
            in_part = np.array([(source.spec_digest, t) in wanted and t in source.trees for t in source.view_trees],
                               bool)
            rows.append(np.stack([np.full(int(in_part.sum()), s), np.flatnonzero(in_part)], axis=1))
        self.rows = np.concatenate(rows).astype(np.int64) if rows else np.zeros((0, 2), np.int64)
        # (source, output) -> a ViewsDataset reading that one PNG column (memory-mapped), opened on first use.
        self._views: dict[tuple[int, str], ViewsDataset] = {}

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_views": {}}

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.rows)

    def _item(self, source: int, output: str, row: int) -> dict:
        """The ViewsDataset item of one views row with one output decoded."""
        key = (source, output)
        if key not in self._views:
            self._views[key] = ViewsDataset(self.data.sources[source].path, outputs=[output])
        return self._views[key][row]

    def styles(self) -> tuple[str, ...]:
        """The input outputs a record may be drawn from: the task's input, then its augmentation styles."""
        return (self.data.task.inputs[0],) + tuple(self.data.task.styles)

    def draw(self, index: int, epoch: int | None = None) -> tuple[str, np.random.Generator | None]:
        """The style record `index` is drawn in at `epoch` and the generator its augmentation continues with
        (None without augmentation): default_rng([seed, epoch, index]), the style choice its first draw."""
        if not self.augment:
            return self.styles()[0], None
        rng = np.random.default_rng([self.seed, self.epoch if epoch is None else int(epoch), int(index)])
        style = self.styles()[0]
        if self.data.task.styles and rng.random() < HAND_STYLE_P:
            style = self.data.task.styles[0]
        return style, rng

    def plain_record(self, index: int, style: str | None = None) -> dict:
        """Item `index` in `style` (default the task's input) as numpy arrays and strings, preprocessed and not
        augmented: what Ray Data decodes in its tasks, the worker augmenting it per epoch (`augmented`)."""
        if not 0 <= index < len(self):
            raise IndexError(f"record {index} out of range [0, {len(self)})")
        task = self.data.task
        style = self.styles()[0] if style is None else style
        s, row = (int(v) for v in self.rows[index])
        source = self.data.sources[s]
        tree_id = str(source.view_trees[row])
        item = self._item(s, style, row)
        raw = _hwc(item[style])
        prepared = prepare(raw, task.input_kind, task.input_size)
        out = {"tree_id": tree_id, "view": int(item["view"]), "spec_digest": source.spec_digest, "style": style,
               "input": prepared.image}
        if task.targets:
            # The target maps and the raw input cut alike; the mask rule is the network family's own.
            cut = {style: apply_crop(raw, prepared.crop, task.input_size, 255)}
            for output in task.targets:
                cut[output] = apply_crop(_hwc(self._item(s, output, row)[output]), prepared.crop,
                                         task.input_size, TARGET_BACKGROUND[output])
            cut = {k: v[None] if v.ndim == 2 else np.moveaxis(v, 2, 0) for k, v in cut.items()}
            family = segment if task.network == "segment" else pix2pix
            _, target, mask = family.targets_from_views(task, cut)
            out["target"], out["mask"] = np.asarray(target), np.asarray(mask)
        else:
            species, params_json = source.trees[tree_id]
            out.update(species=species, params_json=params_json)
        return out

    def augmented(self, plain: dict, rng: np.random.Generator | None) -> dict:
        """`plain` (a plain record in the style `draw` chose) with the augmentation `rng` continues (unchanged for
        None): input, and pix2pix's target and mask, warped alike."""
        if rng is None:
            return plain
        out = dict(plain)
        targets = []
        if "target" in plain:
            targets = [(plain["target"], TARGET_BACKGROUND[self.data.task.targets[0]]), (plain["mask"], (0.0,))]
        draw = segment.augment_photo if self.data.task.network == "segment" else augment
        out["input"], warped = draw(plain["input"], rng, targets)
        if warped:
            out["target"], out["mask"] = warped
        return out

    def record(self, index: int, epoch: int | None = None) -> dict:
        """Item `index` as numpy arrays and strings (augmented with `epoch`, default the dataset's)."""
        style, rng = self.draw(index, epoch)
        return self.augmented(self.plain_record(index, style), rng)

    def __getitem__(self, index: int) -> dict:
        return {k: torch.from_numpy(v) if isinstance(v, np.ndarray) else v for k, v in self.record(index).items()}


def to_ray_dataset(dataset: TaskDataset, epoch: int | None = None, batch_size: int = 16,
                   transform: Callable[[dict], dict] | None = None, columns: Sequence[str] | None = None):
    """The records of `dataset` (same split, same augmentation for `epoch`, default the dataset's) as a
    `ray.data.Dataset` of numpy columns, decoded in Ray tasks, for Ray Train workers
    (`ray.train.get_dataset_shard(...).iter_torch_batches()`). Build one per epoch for fresh augmentation (it is
    lazy). String fields (`tree_id`, `species`, `params_json`, ...) are str columns, which `iter_torch_batches`
    cannot turn into tensors: `transform` maps each record (a dict) to another in the same tasks (e.g. sketchnet's
    codec encoding `params_json` into arrays) and `columns` keeps only the named fields."""
    import ray.data

    chosen = dataset.epoch if epoch is None else int(epoch)
    keep = None if columns is None else list(columns)

    def records(batch: dict) -> dict:
        rows = [dataset.record(int(i), chosen) for i in batch["id"]]
        if transform is not None:
            rows = [transform(row) for row in rows]
        names = keep if keep is not None else list(rows[0])
        missing = [name for name in names if name not in rows[0]]
        if missing:
            raise TrainingDataError(f"record field {missing[0]!r} does not exist: fields are {', '.join(rows[0])}")
        return {name: np.stack([row[name] for row in rows]) if isinstance(rows[0][name], np.ndarray)
                else np.array([row[name] for row in rows]) for name in names}

    return ray.data.range(len(dataset)).map_batches(records, batch_size=batch_size, batch_format="numpy")
