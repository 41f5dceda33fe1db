"""Generation job specifications: a YAML file validated into a frozen `JobSpec`, and the built-in default job.

Input: a YAML mapping (see `DEFAULT_SPEC_YAML` via `farm generate --print-spec`); output: `JobSpec`, or a
`JobSpecError` naming the first bad field, its value and what is allowed.
"""
from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

import renderers
import species
from renderers import CameraError, rig_parts
from species.errors import TreefarmError

__all__ = ["JobSpec", "RenderSpec", "JobSpecError", "PipelineSpec", "DatasetTables", "load_spec", "parse_spec",
           "default_spec", "spec_to_yaml", "species_of_trees", "check_keys", "check_int", "check_number", "check_seed",
           "check_resources", "preset_names"]

_NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


class JobSpecError(TreefarmError):
    """A job specification has a missing, unknown or out-of-range field."""

    subject = "job spec"  # what the message calls the specification

    def __init__(self, field_name: str, value: Any, allowed: str):
        self.field, self.value, self.allowed = field_name, value, allowed
        super().__init__(f"{self.subject} field {field_name!r} = {value!r} is invalid: allowed {allowed}")


@dataclass(frozen=True)
class RenderSpec:
    """How each tree is rendered.

    rig     : view rig name (`tsn4`, `orbit:N`, `two-view`, `two-view:shared`, each optionally `:jitter`).
    size    : image width and height in pixels (16..4096).
    outputs : the maps and sketch styles stored, one views-table column each (`renderers.OUTPUTS` names).
    """

    rig: str = "tsn4"
    size: int = 256
    outputs: tuple[str, ...] = ()


@dataclass(frozen=True)
class DatasetTables:
    """What a job's trees and views tables hold besides the columns every job writes (`farm.dataset` schemas).

    view_outputs : the views table's map and sketch-style columns (`renderers.OUTPUTS` names); empty: no views.
    store_glb    : each trees-table row carries the tree's GLB bytes.
    """

    view_outputs: tuple[str, ...] = ()
    store_glb: bool = False


class PipelineSpec:
    """What `farm.pipeline` reads from a job spec, whatever the kind of job (`JobSpec`, the asset library's
    `LibrarySpec`): fields `name`, `seed`, `shard_size` and `resources` (Ray resources per worker actor), and
    `species_counts` (trees per species), `tables` (a `DatasetTables`), `to_dict()` (the job record, whose
    `render.outputs` readers of the views table use) and `digest()`. Tree i of the plan is
    `species_of_trees(spec)[i]`, grown from `farm.tree_chain.tree_seed(spec.seed, i)`.
    """

    @property
    def n_trees(self) -> int:
        return sum(self.species_counts.values())

    @property
    def n_shards(self) -> int:
        return -(-self.n_trees // self.shard_size)


@dataclass(frozen=True)
class JobSpec(PipelineSpec):
    """One generation job.

    name          : job name; tree ids are f"{name}-{index:08d}".
    seed          : job seed; tree i draws from `numpy.random.SeedSequence(seed).spawn(n)[i]`.
    species       : preset name -> weight (with `trees`) or number of trees (without it), in spec order.
    trees         : total number of trees split over species by weight, or None to read counts per species.
    render        : RenderSpec.
    store_glb     : store each tree's GLB bytes in the trees table.
    shard_size    : trees per shard (one trees and one views part file per shard).
    max_nodes     : a tree whose skeleton has more nodes is recorded as failed before meshing (keeps one
                    runaway parameter draw from stalling a worker for minutes and gigabytes).
    output        : default output location (local path or pyarrow filesystem URI), or None.
    resources     : Ray resources per worker actor (`num_cpus`, `num_gpus`, optional `memory_gb`).
    """

    name: str = "default"
    seed: int = 0
    species: dict[str, float] = field(default_factory=dict)
    trees: int | None = None
    render: RenderSpec = field(default_factory=RenderSpec)
    store_glb: bool = True
    shard_size: int = 8
    max_nodes: int = 300_000
    output: str | None = None
    resources: dict[str, float] = field(default_factory=lambda: {"num_cpus": 1.0, "num_gpus": 0.0})

    # ------------------------------------------------------------------ derived plan facts
    @property
    def tables(self) -> DatasetTables:
        """The render's outputs as views-table columns, and the GLB column when `store_glb`."""
        return DatasetTables(view_outputs=self.render.outputs, store_glb=self.store_glb)

    @property
    def species_counts(self) -> dict[str, int]:
        """Trees per species: the weights as counts, or `trees` split by weight (largest remainder)."""
        names = list(self.species)
        weights = np.array([self.species[n] for n in names], float)
        if self.trees is None:
            return {n: int(w) for n, w in zip(names, weights)}
        quota = self.trees * weights / weights.sum()
        counts = np.floor(quota).astype(int)
        for i in _largest_remainders(quota - counts, self.trees - int(counts.sum())):
            counts[i] += 1
        return {n: int(c) for n, c in zip(names, counts)}

    def to_dict(self) -> dict:
        out = asdict(self)
        out["render"]["outputs"] = list(self.render.outputs)
        return out

    def digest(self) -> str:
        """sha256 of everything that decides the part files' bytes (not `output` or `resources`)."""
        content = self.to_dict()
        for key in ("output", "resources"):
            content.pop(key)
        return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()

    def with_trees(self, total: int) -> "JobSpec":
        """The same job with `total` trees split over the species (`farm generate --trees N`)."""
        check_int("trees", total, 1)
        weights = self.species if self.trees is not None else {n: 1.0 for n in self.species}
        if sum(weights.values()) <= 0:
            raise JobSpecError("species", weights, "at least one positive weight")
        return replace(self, species=dict(weights), trees=total)


def _largest_remainders(remainders: np.ndarray, extra: int) -> list[int]:
    """Indices of the `extra` largest remainders; among equal ones (equal weights), indices spread evenly over
    spec order, so a small job of many species samples every generator rather than the first presets."""
    if extra <= 0:
        return []
    order = np.argsort(-remainders, kind="stable")
    cutoff = remainders[order[extra - 1]]
    above = [int(i) for i in order if remainders[i] > cutoff + 1e-9]
    tied = [int(i) for i in order if abs(remainders[i] - cutoff) <= 1e-9]
    wanted = extra - len(above)
    return above + [tied[int((k + 0.5) * len(tied) / wanted)] for k in range(wanted)]


def species_of_trees(spec: PipelineSpec) -> list[str]:
    """The species of every tree, index order: species interleaved evenly, so any shard mixes them."""
    keys, names = [], []
    for name, count in spec.species_counts.items():
        keys.extend((k + 0.5) / count for k in range(count))
        names.extend([name] * count)
    order = np.argsort(np.array(keys, float), kind="stable")
    return [names[i] for i in order]


# ---------------------------------------------------------------------- field checks of every spec
# Each raises JobSpecError naming the field, its value and what is allowed; the library spec re-raises them as
# its own error class.
_RESOURCE_KEYS = {"num_cpus", "num_gpus", "memory_gb"}
# A worker with its renderer and one small tree needs about this much, with room to spare (its data segment after
# a maple, read from /proc).
MIN_WORKER_MEMORY_GB = 1.0


def check_keys(where: str, mapping: Any, allowed: set[str]) -> dict:
    """`mapping` itself when it is a dict whose keys are all in `allowed`; `where` names it in the error."""
    if not isinstance(mapping, dict):
        raise JobSpecError(where or "spec", mapping, "a mapping")
    for key in mapping:
        if key not in allowed:
            raise JobSpecError(f"{where}.{key}" if where else str(key), mapping[key],
                               f"a known field: {', '.join(sorted(allowed))}")
    return mapping


def check_int(name: str, value: Any, low: int, high: int | None = None) -> int:
    """`value` as an int when it is an integer (not a bool) in [low, high] (no upper bound when high is None)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise JobSpecError(name, value, f"an integer >= {low}")
    if value < low or (high is not None and value > high):
        allowed = f"an integer in [{low}, {high}]" if high is not None else f"an integer >= {low}"
        raise JobSpecError(name, value, allowed)
    return int(value)


def check_number(name: str, value: Any, low: float) -> float:
    """`value` as a float when it is a finite number (not a bool) >= low."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < low:
        raise JobSpecError(name, value, f"a number >= {low}")
    return float(value)


def check_seed(value: Any) -> int:
    """A job seed: an integer in [0, 2^63 - 1] (numpy's SeedSequence takes it whole)."""
    return check_int("seed", value, 0, 2**63 - 1)


def check_resources(raw: Any) -> dict[str, float]:
    """Ray resources per worker actor from a spec's `resources` mapping: num_cpus (default 1) and num_gpus
    (default 0), each a number >= 0, and memory_gb when given (GiB, > 0: Ray's `memory` per actor and the
    worker's own memory limit; without it a worker limits itself to a share of its node's memory)."""
    resources = check_keys("resources", raw, _RESOURCE_KEYS)
    checked = {"num_cpus": check_number("resources.num_cpus", resources.get("num_cpus", 1), 0.0),
               "num_gpus": check_number("resources.num_gpus", resources.get("num_gpus", 0), 0.0)}
    if "memory_gb" in resources:
        checked["memory_gb"] = check_number("resources.memory_gb", resources["memory_gb"], MIN_WORKER_MEMORY_GB)
    return checked


def preset_names() -> list[str]:
    """The names of every species preset (`species.list_presets()`), the default set a spec may name."""
    return [p.name for p in species.list_presets()]


# ---------------------------------------------------------------------- job spec parsing
_TOP_KEYS = {"name", "seed", "species", "trees", "render", "store_glb", "shard_size", "max_nodes", "output",
             "resources"}
_RENDER_KEYS = {"rig", "size", "outputs"}


def _known_outputs() -> Sequence[str]:
    return renderers.OUTPUTS


def _check_rig(rig: Any) -> None:
    try:
        rig_parts(rig)
    except CameraError:
        raise JobSpecError("render.rig", rig, "tsn4, orbit:N[:E1,E2], two-view[:shared], each optionally with "
                           "':jitter', or distinct ones joined by '+'") from None


def _default_outputs() -> Sequence[str]:
    return renderers.DEFAULT_OUTPUTS


def parse_spec(raw: dict, known_species: Sequence[str] | None = None,
               known_outputs: Sequence[str] | None = None) -> JobSpec:
    """Validate a spec mapping (as loaded from YAML) into a JobSpec; the first bad field raises JobSpecError.

    `known_species` / `known_outputs` default to `species.list_presets()` / `renderers.OUTPUTS`.
    """
    raw = check_keys("", raw, _TOP_KEYS)
    name = raw.get("name", "default")
    if not isinstance(name, str) or not _NAME_PATTERN.match(name):
        raise JobSpecError("name", name, "1-64 letters, digits, '_', '-' or '.', starting with a letter or digit")
    seed = check_seed(raw.get("seed", 0))

    trees = raw.get("trees")
    if trees is not None:
        trees = check_int("trees", trees, 1)
    mix = raw.get("species")
    if not isinstance(mix, dict) or not mix:
        raise JobSpecError("species", mix, "a non-empty mapping of preset name -> count (or weight with `trees`)")
    known = list(known_species) if known_species is not None else preset_names()
    species_mix: dict[str, float] = {}
    for preset, amount in mix.items():
        if preset not in known:
            raise JobSpecError(f"species.{preset}", preset, f"a known species: {', '.join(sorted(known))}")
        if trees is None:
            species_mix[preset] = float(check_int(f"species.{preset}", amount, 0))
        else:
            species_mix[preset] = check_number(f"species.{preset}", amount, 0.0)
    if sum(species_mix.values()) <= 0:
        raise JobSpecError("species", mix, "at least one positive weight" if trees is not None
                           else "at least one tree (a job of zero trees writes nothing)")

    render_raw = check_keys("render", raw.get("render", {}), _RENDER_KEYS)
    rig = render_raw.get("rig", "tsn4")
    _check_rig(rig)
    size = check_int("render.size", render_raw.get("size", 256), 16, 4096)
    outputs_known = list(known_outputs) if known_outputs is not None else list(_known_outputs())
    outputs = render_raw.get("outputs")
    if outputs is None:
        outputs = list(_default_outputs())
    if not isinstance(outputs, (list, tuple)):
        raise JobSpecError("render.outputs", outputs, f"a list of outputs from: {', '.join(outputs_known)}")
    for output in outputs:
        if output not in outputs_known:
            raise JobSpecError("render.outputs", output, f"outputs from: {', '.join(outputs_known)}")
    if len(set(outputs)) != len(outputs):
        raise JobSpecError("render.outputs", list(outputs), "each output at most once")

    store_glb = raw.get("store_glb", True)
    if not isinstance(store_glb, bool):
        raise JobSpecError("store_glb", store_glb, "true or false")
    shard_size = check_int("shard_size", raw.get("shard_size", 8), 1, 100_000)
    max_nodes = check_int("max_nodes", raw.get("max_nodes", 300_000), 1)
    output = raw.get("output")
    if output is not None and (not isinstance(output, str) or not output):
        raise JobSpecError("output", output, "a path or URI string")
    resources = check_resources(raw.get("resources", {}))
    return JobSpec(name=name, seed=seed, species=species_mix, trees=trees,
                   render=RenderSpec(rig=rig, size=size, outputs=tuple(outputs)), store_glb=store_glb,
                   shard_size=shard_size, max_nodes=max_nodes, output=output, resources=resources)


def load_spec(path: str | Path, parse: Callable[..., Any] | None = None, **known):
    """Read a YAML spec file and validate it with `parse` (default `parse_spec`, giving a JobSpec; the asset
    library passes its own parser): the one loader of every farm spec file."""
    import yaml

    parse = parse_spec if parse is None else parse
    path = Path(path)
    if not path.is_file():
        raise JobSpecError("spec file", str(path), "an existing YAML file")
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise JobSpecError("spec file", str(path), f"valid YAML ({' '.join(str(exc).split())})") from None
    return parse(raw, **known)


def default_spec() -> JobSpec:
    """The built-in job: every preset, 2 trees each, default outputs, rig tsn4 at 256 px, shards of 8."""
    return parse_spec({"name": "default", "seed": 0, "species": {name: 2 for name in preset_names()},
                       "render": {"rig": "tsn4", "size": 256, "outputs": list(_default_outputs())},
                       "shard_size": 8})


def spec_to_yaml(spec: JobSpec) -> str:
    """The spec as YAML that `load_spec` reads back to an equal JobSpec."""
    import yaml

    content = spec.to_dict()
    if content["trees"] is None:
        content["species"] = {k: int(v) for k, v in content["species"].items()}
    return yaml.safe_dump(content, sort_keys=False)
