"""TreeSketchNet's parameter codec: a Weber-Penn dictionary to the network's targets and back.

In: `draws: realized` Weber-Penn dictionaries (treefarm's presets, TreeSketchNet's dictionaries). Out: per head, a
vector of normalised values (float32) with a mask, or a class index (int64); and, from the network's outputs, a
dictionary `species.grow` accepts (integers rounded, classes snapped to those training held, values clamped to
their training range, a tree past the size budget shrunk: see `ParameterCodec.decode_arrays`).

Normalisation (fitted, stored by `to_dict`): floats divided by a power of two at or above their largest training
magnitude (the paper's max-abs scaling), integers min-max scaled; why a power of two: `_fit_stats`.

The key-to-head table is the paper's: its 62 Sapling keys (the 70 of its dictionaries but `seed` and the seven
`prune*` keys) by value range into six regression heads, per-level keys as 4 values and scalars as 1 (the paper
repeats a scalar in 4 slots, which would weigh it 4 times in the loss); the categorical keys get one
classification head each, and `rSplits2` is not predicted, so 61 keys are. Four keys of ours that change the tree
(`splitByLen`, `autoTaper`, `closeTip`, `rMode`) get classification heads too: our presets grow with
`splitByLen: true`, TreeSketchNet's dictionaries without it.

Stored draws: the network predicts Sapling's realized draws (`scaleV`, `curveV1`, `rLastAng`, ...) as the paper
does. A dictionary that lacks one is encoded with the value the generator uses in its absence (0 offsets, factor
1, sign +1), so it grows the same tree; `rLastAng`, which the generator draws from the rng when absent, is masked
out of the loss instead. `rSplits2` is neither encoded nor decoded: decode leaves the split decisions to the seed,
as the presets do. A `draws: ranges` dictionary (Sapling's own presets) holds variation ranges, not draws, and is
refused. Decode always writes `draws: realized`, `generator: weber_penn`, the predicted `species`, the `seed` it is
given, and the pruning keys and colours of the predicted species' preset (the paper does not learn pruning, and
keeps it at Sapling's defaults; our weeping willow prunes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping, Sequence

import numpy as np

from species import get_preset, list_presets
from species.errors import TreefarmError
from species.weber_penn import (MAX_ESTIMATED_STEMS_PER_LEVEL, SCHEMA, WeberPennParams, draws_semantics,
                                estimate_size, validate)

__all__ = ["ParameterCodec", "CodecError", "CODEC_VERSION", "HEAD_TABLE", "REGRESSION_HEADS", "CLASS_KEYS",
           "SPECIES_HEAD", "PREDICTED_KEYS", "SPECIES_KEYS", "class_head", "class_values", "slot_names",
           "species_fixed_values", "weber_penn_species"]

CODEC_VERSION = "sketchnet-codec/1"

# head name -> (the paper's value range, the keys in it). Where the paper's Table 1 names a key's range it is
# followed (leafScale and nrings [0, inf), forks [min, max], the angles [-360, 360]); the rest by the range of
# the values themselves (realized factors such as leafScaleV and scaleV0 lie around 1, hence [0, inf)).
HEAD_TABLE: dict[str, tuple[str, tuple[str, ...]]] = {
    "unit": ("[0, 1]", ("attractOut", "baseSize", "baseSize_s", "customShape", "lengthV", "taper", "splitHeight",
                        "ratio", "minRadius", "radiusTweak", "taperCrown")),
    "signed_unit": ("[-1, 1]", ("leafScaleT",)),
    "positive": ("[0, inf)", ("scale", "scale0", "length", "branchDist", "ratioPower", "rootFlare", "leafScale",
                              "leafScaleX", "segSplits", "scaleV0", "leafScaleV", "nrings", "branches", "curveRes",
                              "resU", "bevelRes")),
    "real": ("(-inf, inf)", ("attractUp", "splitBias", "scaleV", "leaves")),
    "angle": ("[-360, 360]", ("curve", "curveBack", "curveV1", "curveV2", "downAngle", "downAngleV", "rotate",
                              "rotateV", "splitAngle", "splitAngleV1", "splitAngleV2", "rLastAng", "leafDownAngle",
                              "leafDownAngleV", "leafRotate", "leafRotateV", "leafangle")),
    "bounded": ("[min, max]", ("levels", "baseSplits", "maxBaseSplits")),
}
REGRESSION_HEADS = tuple(HEAD_TABLE)
# The paper's categorical keys, then ours that change the tree.
CLASS_KEYS = ("shape", "shapeS", "leafDist", "leafShape", "horzLeaves", "useOldDownAngle", "useParentAngle",
              "choiceNegPos1", "choiceNegPos2", "splitByLen", "autoTaper", "closeTip", "rMode")
PAPER_CLASS_KEYS = CLASS_KEYS[:9]
PREDICTED_KEYS = tuple(k for _, keys in HEAD_TABLE.values() for k in keys) + PAPER_CLASS_KEYS
SPECIES_HEAD = "species"
PRUNE_KEYS = ("prune", "pruneBase", "prunePowerHigh", "prunePowerLow", "pruneRatio", "pruneWidth", "pruneWidthPeak")
# Not predicted, taken by decode from the predicted species' preset (the paper's fixed parameters identify a
# species; our weeping willow prunes). `seed` comes from decode's caller, `rSplits2` from nowhere.
SPECIES_KEYS = PRUNE_KEYS + ("bark_color", "leaf_color")
# Realized draws a dictionary may lack: the value the generator uses then, or None where it draws from the rng.
ABSENT_DRAW_VALUES: dict[str, Any] = {
    "scaleV": 0.0, "scaleV0": 1.0, "leafScaleV": 1.0, "curveV1": [0.0] * 4, "curveV2": [0.0] * 4,
    "splitAngleV1": [0.0] * 4, "splitAngleV2": [0.0] * 4, "choiceNegPos1": 1, "choiceNegPos2": 1, "rLastAng": None,
}
# What decode shrinks, toward the training value nearest zero, when a prediction would grow a tree past the size
# budget (the keys that multiply the stem count), and the budget: this many times the largest training tree.
SIZE_DRIVERS = ("branches", "segSplits", "baseSplits", "leaves")
SIZE_BUDGET_FACTOR = 4.0
SIZE_FIT_SAMPLES = 1000  # training dictionaries whose size is estimated, evenly spaced
PER_LEVEL = ("float4", "int4")
INTEGER = ("int", "int4")


class CodecError(TreefarmError):
    """A dictionary the codec cannot encode, outputs it cannot decode, or a stored codec it cannot read."""


def class_head(key: str) -> str:
    """The output name of a categorical key's classification head."""
    return f"class_{key}"


def class_values(key: str) -> tuple:
    """The values a categorical key's classes stand for, in class order (from the schema, so head sizes are
    fixed by the code, not by the data)."""
    spec = SCHEMA[key]
    if key.startswith("choiceNegPos"):
        return (-1, 1)  # the generator reads 0 and -1 alike as negative
    if spec.kind == "bool":
        return (False, True)
    if spec.kind == "shape":
        return tuple(range(int(spec.low), int(spec.high) + 1))
    return tuple(spec.options)


def weber_penn_species() -> tuple[str, ...]:
    """The species vocabulary: the Weber-Penn preset names, sorted (the trees table's `species` labels)."""
    return tuple(sorted(p.name for p in list_presets("weber_penn")))


@dataclass(frozen=True)
class _Slot:
    key: str
    level: int | None   # index into a per-level key's 4 values; None for a scalar key


def _slots(keys: Sequence[str]) -> tuple[_Slot, ...]:
    return tuple(_Slot(k, level) for k in keys
                 for level in (range(4) if SCHEMA[k].kind in PER_LEVEL else (None,)))


SLOTS: dict[str, tuple[_Slot, ...]] = {head: _slots(keys) for head, (_, keys) in HEAD_TABLE.items()}


def slot_names(head: str) -> list[str]:
    """Names of a regression head's values (`length[2]`, `scale`), in output order."""
    if head not in SLOTS:
        raise CodecError(f"unknown regression head {head!r}; known: {list(SLOTS)}")
    return [s.key if s.level is None else f"{s.key}[{s.level}]" for s in SLOTS[head]]


def _prepared(params: Mapping) -> dict:
    """`validate`'s copy of a realized Weber-Penn dictionary with absent draws filled; CodecError otherwise."""
    if not isinstance(params, Mapping):
        raise CodecError(f"a parameter dictionary must be a dict; got {type(params).__name__}")
    generator = params.get("generator", "weber_penn")
    if generator != "weber_penn":
        raise CodecError(f"TreeSketchNet's codec encodes Weber-Penn dictionaries; got generator {generator!r}")
    if draws_semantics(dict(params)) != "realized":
        raise CodecError("a `draws: ranges` dictionary (Sapling's own presets) holds variation ranges, not the "
                         "realized draws TreeSketchNet predicts; sample a treefarm preset or a `draws: realized` "
                         "dictionary instead")
    out = validate(dict(params))
    for key, value in ABSENT_DRAW_VALUES.items():
        if key not in out and value is not None:
            out[key] = list(value) if isinstance(value, list) else value
    return out


def _values(prepared: Sequence[dict], head: str) -> tuple[np.ndarray, np.ndarray]:
    """(B, n) float64 values of a head's slots and (B, n) float32 presence (0 where a draw is absent)."""
    values = np.zeros((len(prepared), len(SLOTS[head])))
    present = np.ones_like(values, dtype=np.float32)
    for column, slot in enumerate(SLOTS[head]):
        for row, params in enumerate(prepared):
            if slot.key not in params:
                present[row, column] = 0.0
                continue
            value = params[slot.key]
            values[row, column] = value if slot.level is None else value[slot.level]
    return values, present


def _level_mask(prepared: Sequence[dict], head: str) -> np.ndarray:
    """(B, n) float32: 1 where a slot is used, 0 on the levels a dictionary does not grow (level >= levels)."""
    levels = np.array([p["levels"] for p in prepared])[:, None]
    slot_level = np.array([-1 if s.level is None else s.level for s in SLOTS[head]])[None, :]
    return (slot_level < levels).astype(np.float32)


def _class_index(key: str, value: Any) -> int:
    if key.startswith("choiceNegPos"):
        return int(value > 0)
    return class_values(key).index(value)


@dataclass(frozen=True)
class _Limits:
    """Fitted limits of a decoded tree: the smallest tree scale (scale + scaleV, metres), and the size budget in
    estimated stem nodes and leaves (`species.weber_penn.estimate_size`)."""

    min_tree_scale: float
    max_nodes: float
    max_leaves: float


@dataclass(frozen=True, eq=False)
class _Stats:
    """Per-slot normalisation (normalised = (value - offset) / scale), training mean and decode bounds of one
    regression head, (n,) float64 each, in the dictionary's units."""

    offset: np.ndarray
    scale: np.ndarray
    mean: np.ndarray
    low: np.ndarray
    high: np.ndarray


class ParameterCodec:
    """TreeSketchNet's targets: the key-to-head table, a normalisation fitted on training dictionaries, the
    class frequencies (the trivial baseline's), the species vocabulary and the limits of a decoded tree. Build
    with `fit` or `from_dict`."""

    def __init__(self, stats: dict[str, _Stats], class_counts: dict[str, np.ndarray], species: Sequence[str],
                 limits: _Limits):
        self._stats = stats
        self._class_counts = class_counts
        self.species: tuple[str, ...] = tuple(species)
        self._limits = limits

    # ------------------------------------------------------------------------------------------ structure
    @property
    def keys(self) -> tuple[str, ...]:
        """The dictionary keys the network predicts: the paper's 61 and our 4 categorical ones."""
        return PREDICTED_KEYS + CLASS_KEYS[len(PAPER_CLASS_KEYS):]

    @property
    def head_sizes(self) -> dict[str, int]:
        """Output name -> width, in output order: regression heads (values), then classification heads
        (classes); the species head is `n_species` wide."""
        sizes = {head: len(SLOTS[head]) for head in REGRESSION_HEADS}
        sizes.update({class_head(k): len(class_values(k)) for k in CLASS_KEYS})
        return sizes

    @property
    def n_species(self) -> int:
        return len(self.species)

    @property
    def output_sizes(self) -> dict[str, int]:
        """Every network output's width: `head_sizes` and the species head."""
        return {**self.head_sizes, SPECIES_HEAD: self.n_species}

    # ------------------------------------------------------------------------------------------ fitting
    @classmethod
    def fit(cls, dicts: Sequence[Mapping], species: Sequence[str] | None = None) -> ParameterCodec:
        """Fit on training dictionaries: the normalisation (`_fit_stats`), the decode bounds (each value's training
        minimum and maximum), the means and class frequencies (the trivial baseline) and the limits of a decoded
        tree. `species`: the vocabulary, by default the Weber-Penn preset names."""
        if len(dicts) == 0:
            raise CodecError("cannot fit TreeSketchNet's codec on no dictionaries: give at least one")
        vocabulary = weber_penn_species() if species is None else tuple(species)
        if len(vocabulary) == 0 or len(set(vocabulary)) != len(vocabulary):
            raise CodecError(f"the species vocabulary must be non-empty names without repeats; got {vocabulary}")
        prepared = [_prepared(d) for d in dicts]
        stats = {head: _fit_stats(*_values(prepared, head), head) for head in REGRESSION_HEADS}
        counts = {k: np.bincount([_class_index(k, p[k]) for p in prepared], minlength=len(class_values(k)))
                  for k in CLASS_KEYS}
        labels = [i for i in (_species_index(vocabulary, p) for p in prepared) if i >= 0]
        counts[SPECIES_HEAD] = np.bincount(labels, minlength=len(vocabulary))
        sized = [_estimate(p) for p in prepared[::max(1, math.ceil(len(prepared) / SIZE_FIT_SAMPLES))]]
        limits = _Limits(
            # Half the smallest training tree: a floor for decode's scale + scaleV that no training value is near.
            min_tree_scale=0.5 * min(p["scale"] + p["scaleV"] for p in prepared),
            max_nodes=SIZE_BUDGET_FACTOR * max(e.total_nodes for e in sized),
            max_leaves=SIZE_BUDGET_FACTOR * max(max(e.leaves for e in sized), 1.0))
        return cls(stats, counts, vocabulary, limits)

    # ------------------------------------------------------------------------------------------ encoding
    def encode(self, params: Mapping, dtype=np.float32) -> dict[str, np.ndarray]:
        """One dictionary as targets: per regression head `HEAD` (n,) normalised values (`dtype`: float32 for
        training; float64 decodes to the dictionary's values exactly) and `HEAD_mask` (n,) float32 (0 on unused
        levels and absent draws); per classification head () int64 class index; `species` () int64, -1 where the
        dictionary names no species (`custom` or none). Raises CodecError or ParameterError naming a bad key."""
        return {name: array[0] for name, array in self.encode_arrays([params], dtype).items()}

    def encode_arrays(self, dicts: Sequence[Mapping], dtype=np.float32) -> dict[str, np.ndarray]:
        """`encode` of several dictionaries, stacked: (B, n) and (B,) numpy arrays."""
        if len(dicts) == 0:
            raise CodecError("nothing to encode: give at least one dictionary")
        prepared = [_prepared(d) for d in dicts]
        out: dict[str, np.ndarray] = {}
        for head in REGRESSION_HEADS:
            values, present = _values(prepared, head)
            stats = self._stats[head]
            out[head] = ((values - stats.offset) / stats.scale).astype(dtype)
            out[f"{head}_mask"] = present * _level_mask(prepared, head)
        for key in CLASS_KEYS:
            out[class_head(key)] = np.array([_class_index(key, p[key]) for p in prepared], np.int64)
        out[SPECIES_HEAD] = np.array([_species_index(self.species, p) for p in prepared], np.int64)
        return out

    def encode_batch(self, dicts: Sequence[Mapping]):
        """`encode_arrays` as torch tensors (float32 and int64), for the loss."""
        import torch  # optional here: the codec itself serves ONNX predictors without torch

        return {name: torch.from_numpy(array) for name, array in self.encode_arrays(dicts).items()}

    def as_outputs(self, encoded: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Targets (from `encode` or `encode_arrays`) as network outputs that decode to them: regression values as
        they are, class indices as one-hot logits (an absent species as all zeros)."""
        out: dict[str, np.ndarray] = {head: np.asarray(encoded[head]) for head in REGRESSION_HEADS}
        for name, width in self.output_sizes.items():
            if name not in out:
                out[name] = (np.asarray(encoded[name], np.int64)[..., None] == np.arange(width)).astype(np.float32)
        return out

    def baseline_outputs(self, batch_size: int) -> dict[str, np.ndarray]:
        """The trivial baseline's outputs, (batch_size, width) each: every value at its training mean, every class
        head at its training frequencies (their logarithms, as logits)."""
        out: dict[str, np.ndarray] = {}
        for head in REGRESSION_HEADS:
            stats = self._stats[head]
            out[head] = np.tile(((stats.mean - stats.offset) / stats.scale).astype(np.float32), (batch_size, 1))
        for name, counts in self._class_counts.items():
            logits = np.log(np.maximum(counts, 1e-3) / max(counts.sum(), 1)).astype(np.float32)
            out[name if name == SPECIES_HEAD else class_head(name)] = np.tile(logits, (batch_size, 1))
        return out

    # ------------------------------------------------------------------------------------------ decoding
    def decode(self, outputs: Mapping[str, Any], seed: int = 0) -> dict:
        """The dictionary one sample's outputs (regression heads (n,), classification logits (classes,),
        species logits (n_species,)) describe; `species.grow` accepts it whatever the values (see `decode_arrays`)."""
        return self.decode_arrays({name: _numpy(value)[None] for name, value in outputs.items()}, seed)[0]

    def decode_batch(self, outputs: Mapping[str, Any], seed: int = 0) -> list[dict]:
        """`decode` of a batch of outputs: torch tensors or numpy arrays with a leading batch axis."""
        return self.decode_arrays({name: _numpy(value) for name, value in outputs.items()}, seed)

    def species_confidence(self, outputs: Mapping[str, np.ndarray]) -> np.ndarray:
        """(B,) float64 on [0, 1]: the softmax probability of the species `decode_arrays` reads, over the species
        training held (the others cannot be read)."""
        scores = _held_scores(outputs[SPECIES_HEAD], self._class_counts[SPECIES_HEAD])
        best = scores.max(axis=1)
        read = np.isfinite(best)  # else no finite score: the pick is `_argmax`'s most frequent class, a guess
        total = np.exp(scores[read] - best[read, None]).sum(axis=1)
        confidence = np.zeros(len(best))
        confidence[read] = 1.0 / total
        return confidence

    def species_ranking(self, outputs: Mapping[str, np.ndarray]) -> list[tuple[str, float]]:
        """The species training held, most likely first, with their softmax probabilities, for the first sample of
        `outputs` (what `species_confidence` gives the first of)."""
        scores = _held_scores(outputs[SPECIES_HEAD], self._class_counts[SPECIES_HEAD])[0]
        held = np.flatnonzero(np.isfinite(scores))
        if held.size == 0:
            return [(self.species[int(_argmax(outputs[SPECIES_HEAD][:1], self._class_counts[SPECIES_HEAD])[0])], 0.0)]
        weights = np.exp(scores[held] - scores[held].max())
        order = np.argsort(-scores[held], kind="stable")
        return [(self.species[int(held[i])], float(weights[i] / weights.sum())) for i in order]

    def normalised_range(self, head: str) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) (n,) of a regression head's outputs: the values `decode_arrays` keeps unclamped."""
        stats = self._stats[head]
        return (stats.low - stats.offset) / stats.scale, (stats.high - stats.offset) / stats.scale

    def decode_arrays(self, outputs: Mapping[str, np.ndarray], seed: int = 0) -> list[dict]:
        """Dictionaries from (B, width) numpy outputs: values un-normalised, clamped to their training range
        (NaN read as 0, infinities as huge) and integers rounded; each class head's most likely class among those
        training held; scale + scaleV kept above half the smallest training tree; a tree whose estimated size
        exceeds the budget shrunk (`_within_budget`); the species' preset values of SPECIES_KEYS, `seed`."""
        self._check_outputs(outputs)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise CodecError(f"decode seed must be a non-negative integer; got {seed!r}")
        columns = {head: self._denormalised(head, np.asarray(outputs[head], np.float64)) for head in REGRESSION_HEADS}
        classes = {key: _argmax(outputs[class_head(key)], self._class_counts[key]) for key in CLASS_KEYS}
        species = _argmax(outputs[SPECIES_HEAD], self._class_counts[SPECIES_HEAD])
        dicts = []
        for row in range(len(species)):
            params: dict[str, Any] = {"generator": "weber_penn", "draws": "realized"}
            for head, values in columns.items():
                for slot, value in zip(SLOTS[head], values[row].tolist()):
                    if slot.level is None:
                        params[slot.key] = value
                    else:
                        params.setdefault(slot.key, [None] * 4)[slot.level] = value
            params.update({key: class_values(key)[index[row]] for key, index in classes.items()})
            # validate's one cross-key rule: the tree's scale (scale + scaleV) stays positive.
            params["scaleV"] = max(params["scaleV"], self._limits.min_tree_scale - params["scale"])
            params["species"] = self.species[species[row]]
            params["seed"] = seed
            params.update(species_fixed_values(params["species"]))
            dicts.append(self._within_budget(params))
        return dicts

    def _check_outputs(self, outputs: Mapping[str, np.ndarray]) -> None:
        missing = [name for name in self.output_sizes if name not in outputs]
        if missing:
            raise CodecError(f"network outputs lack {missing}; TreeSketchNet's codec needs {list(self.output_sizes)}")
        batch = np.shape(outputs[REGRESSION_HEADS[0]])[:1]
        for name, width in self.output_sizes.items():
            shape = np.shape(outputs[name])
            if len(shape) != 2 or shape[1] != width or shape[:1] != batch:
                raise CodecError(f"network output {name!r} has shape {shape}; expected {(*batch, width)}")

    def _denormalised(self, head: str, normalised: np.ndarray) -> np.ndarray:
        """(B, n) values as the dictionary holds them: un-normalised, clamped to the training range, integers
        rounded; an object array of Python floats and ints."""
        stats = self._stats[head]
        finite = np.nan_to_num(normalised, nan=0.0, posinf=1e6, neginf=-1e6)
        values = np.clip(stats.offset + stats.scale * finite, stats.low, stats.high)
        integer = np.array([SCHEMA[s.key].kind in INTEGER for s in SLOTS[head]])
        return np.where(integer, np.rint(values).astype(np.int64).astype(object), values.astype(object))

    def _within_budget(self, params: dict) -> dict:
        """`params`, or where its estimated size exceeds the budget, its SIZE_DRIVERS moved toward the training
        value nearest zero, by the smallest step (bisected) that fits; failing that, fewer levels."""
        if self._fits(params):
            return params
        nearest_zero = {key: self._nearest_zero(key) for key in SIZE_DRIVERS}

        def shrunk(fraction: float, levels: int) -> dict:
            out = {**params, "levels": levels}
            for key, floor in nearest_zero.items():
                value = floor + fraction * (np.asarray(params[key], np.float64) - floor)
                value = np.rint(value).astype(np.int64) if SCHEMA[key].kind in INTEGER else value
                out[key] = value.tolist()
            return out

        for levels in range(params["levels"], 0, -1):
            if self._fits(shrunk(0.0, levels)):
                low, high = 0.0, 1.0
                for _ in range(12):
                    middle = 0.5 * (low + high)
                    low, high = (middle, high) if self._fits(shrunk(middle, levels)) else (low, middle)
                return shrunk(low, levels)
        raise CodecError("no decoded tree fits the codec's size budget even with one level and the smallest "
                         f"training {', '.join(SIZE_DRIVERS)}; refit the codec on dictionaries that grow")

    def _fits(self, params: dict) -> bool:
        estimate = _estimate(validate(params))
        return (estimate.total_nodes <= self._limits.max_nodes and estimate.leaves <= self._limits.max_leaves
                and max(estimate.splines) <= MAX_ESTIMATED_STEMS_PER_LEVEL)

    def _nearest_zero(self, key: str) -> np.ndarray:
        """A size driver's training value nearest zero: (4,) for a per-level key, () for a scalar."""
        head = next(h for h, (_, keys) in HEAD_TABLE.items() if key in keys)
        columns = [i for i, slot in enumerate(SLOTS[head]) if slot.key == key]
        stats = self._stats[head]
        values = np.clip(0.0, stats.low[columns], stats.high[columns])
        return values if SCHEMA[key].kind in PER_LEVEL else values[0]

    # ------------------------------------------------------------------------------------------ storage
    def to_dict(self) -> dict:
        """A JSON-able copy (stored beside the model); `from_dict` reads it back."""
        return {
            "version": CODEC_VERSION,
            "heads": {head: {"range": HEAD_TABLE[head][0], "values": slot_names(head),
                             **{f: getattr(self._stats[head], f).tolist() for f in _names(_Stats)}}
                      for head in REGRESSION_HEADS},
            "classes": {key: {"values": list(class_values(key)), "counts": self._class_counts[key].tolist()}
                        for key in CLASS_KEYS},
            "species": {"values": list(self.species), "counts": self._class_counts[SPECIES_HEAD].tolist()},
            "limits": {f: getattr(self._limits, f) for f in _names(_Limits)},
        }

    @classmethod
    def from_dict(cls, data: Mapping) -> ParameterCodec:
        """Read `to_dict`'s output; CodecError when it was written by another codec version or is malformed."""
        if not isinstance(data, Mapping):
            raise CodecError(f"a stored codec must be a JSON object; got {type(data).__name__}")
        version = data.get("version")
        if version != CODEC_VERSION:
            raise CodecError(f"stored codec version {version!r} does not match this code's {CODEC_VERSION!r}: "
                             "retrain the model with this version of treefarm, or load it with the version that "
                             "trained it")
        try:
            stats = {}
            for head in REGRESSION_HEADS:
                stored = data["heads"][head]
                if list(stored["values"]) != slot_names(head):
                    raise CodecError(f"stored codec head {head!r} holds values {stored['values']}, not this code's")
                stats[head] = _Stats(*(_array(stored[f], len(SLOTS[head]), f"{head}.{f}") for f in _names(_Stats)))
            counts = {}
            for key in CLASS_KEYS:
                stored = data["classes"][key]
                if list(stored["values"]) != list(class_values(key)):
                    raise CodecError(f"stored codec classes of {key!r} are {stored['values']}, not this code's "
                                     f"{list(class_values(key))}")
                counts[key] = _counts(stored["counts"], len(class_values(key)), key)
            species = tuple(data["species"]["values"])
            counts[SPECIES_HEAD] = _counts(data["species"]["counts"], len(species), SPECIES_HEAD)
            limits = _Limits(*(float(data["limits"][f]) for f in _names(_Limits)))
        except (KeyError, TypeError, ValueError) as exc:
            raise CodecError(f"stored codec is malformed ({type(exc).__name__}: {exc}); it was not written by "
                             "ParameterCodec.to_dict") from None
        bad = [f for f in _names(_Limits) if not (math.isfinite(getattr(limits, f)) and getattr(limits, f) > 0)]
        if bad:
            raise CodecError(f"stored codec limit {bad[0]} = {getattr(limits, bad[0])!r}; allowed a positive number")
        return cls(stats, counts, species, limits)


def _fit_stats(values: np.ndarray, present: np.ndarray, head: str) -> _Stats:
    """One head's normalisation over the dictionaries that hold each value. A float is divided by the power of two
    at or above its largest training magnitude (the paper's max-abs scaling, to [-1, 1]): a power of two makes
    decode exact in float64, and float32 targets decode to the float32 rounding of the value, because the Weber-Penn
    generator is discontinuous in its parameters (a count rounds, a split chance crosses a threshold) and a value
    off by one unit in the last place can grow another tree. An integer is min-max scaled to [0, 1] (rounding makes
    it exact). A value no dictionary holds keeps the schema's range."""
    count = present.sum(axis=0)
    held = present > 0
    spans = np.array([[SCHEMA[s.key].low, SCHEMA[s.key].high] for s in SLOTS[head]], np.float64)
    low = np.where(count > 0, np.where(held, values, np.inf).min(axis=0), spans[:, 0])
    high = np.where(count > 0, np.where(held, values, -np.inf).max(axis=0), spans[:, 1])
    mean = np.where(count > 0, (values * held).sum(axis=0) / np.maximum(count, 1), (low + high) / 2)
    integer = np.array([SCHEMA[s.key].kind in INTEGER for s in SLOTS[head]])
    magnitude = np.maximum(np.abs(low), np.abs(high))
    power_of_two = np.exp2(np.ceil(np.log2(np.where(magnitude > 0, magnitude, 1.0))))
    # Widened to the float32 roundings of the extremes, so float32 targets decode to the float32 value unclamped.
    low = np.where(integer, low, np.maximum(np.minimum(low, low.astype(np.float32)), spans[:, 0]))
    high = np.where(integer, high, np.minimum(np.maximum(high, high.astype(np.float32)), spans[:, 1]))
    offset = np.where(integer, low, 0.0)
    scale = np.where(integer, np.maximum(high - low, 1.0), power_of_two)
    return _Stats(offset, scale, mean, low, high)


def _species_index(vocabulary: Sequence[str], params: Mapping) -> int:
    name = params.get("species", "custom")
    if name == "custom":
        return -1
    if name not in vocabulary:
        raise CodecError(f"species {name!r} is not in the codec's vocabulary {list(vocabulary)}")
    return vocabulary.index(name)


def species_fixed_values(name: str) -> dict:
    """The values of SPECIES_KEYS that the preset a species label names fixes (none for a label with no preset):
    what a decoded dictionary takes from its predicted species."""
    try:
        fixed = get_preset(name).fixed
    except TreefarmError:
        return {}
    return {key: list(fixed[key]) if isinstance(fixed[key], list) else fixed[key]
            for key in SPECIES_KEYS if key in fixed}


def _held_scores(logits: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(B, classes) float64: the logits with NaN lowest and the classes training never held (when it held any)
    at -inf."""
    scores = np.nan_to_num(np.asarray(logits, np.float64), nan=-np.inf, posinf=np.finfo(np.float64).max)
    return np.where(counts > 0, scores, -np.inf) if counts.any() else scores


def _argmax(logits: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(B,) int: the class of highest logit among those training held (all, if it held none), NaN lowest.
    A class no training tree had cannot be learned, and some never grow (shapeS 8 needs a custom profile)."""
    scores = _held_scores(logits, counts)
    best = np.argmax(scores, axis=1)
    # A row of only -inf scores argmaxes to class 0, which training may not hold: take its most frequent class.
    return np.where(np.isfinite(scores.max(axis=1)), best, int(np.argmax(counts)))


def _estimate(validated: dict):
    """`estimate_size` of a validated dictionary (its stored draws make the rng unused but for absent rLastAng,
    which does not change the size)."""
    return estimate_size(WeberPennParams.from_validated(validated, np.random.default_rng(0)))


def _names(cls) -> list[str]:
    return [f.name for f in fields(cls)]


def _counts(values, size: int, name: str) -> np.ndarray:
    array = np.asarray(values, np.int64)
    if array.shape != (size,) or (array < 0).any():
        raise CodecError(f"stored codec counts of {name} must be {size} non-negative integers; got {values!r}")
    return array


def _array(values, size: int, name: str) -> np.ndarray:
    array = np.asarray(values, np.float64)
    if array.shape != (size,) or not np.isfinite(array).all():
        raise CodecError(f"stored codec entry {name} must be {size} finite numbers; got shape {array.shape}")
    return array


def _numpy(value) -> np.ndarray:
    """A torch tensor or array-like as a numpy array (torch stays an optional import)."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value)
