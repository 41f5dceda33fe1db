"""The training tasks, one registry (`TASKS`): what each network reads and learns, which job spec makes its data.

In: a task name and dataset folders; out: `Task` records (inputs, targets, the network family that learns them and,
for pix2pix, how the target's channels are used), dataset checks that name the missing output and the spec that
makes it (`TrainingDataError`), and the shipped job specs as YAML text (`print_data_spec`). Everything that lists
or looks up tasks (`farm train`, the training loop, the model registry, `benchmarks/bench_train.py`) reads
`TASKS`, so a new task is one entry here.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from farm.dataset import DatasetError, read_manifest
from farm.dataset.storage import Location
from species.errors import TreefarmError

__all__ = ["Task", "TASKS", "NETWORKS", "JUDGED_BY", "SPECS_DIR", "TrainingDataError", "MissingOutputError", "get_task",
           "print_data_spec"]

SPECS_DIR = Path(__file__).resolve().parent / "specs"
# The network families `trainers.networks.network_for` builds, with the held-out metric that judges a model of the
# family and whether higher is better: TreeSketchNet (a sketch to a parameter dictionary and its species),
# pix2pix (a sketch to depth maps) and segment (a photo to its tree mask). The registry's tables read it without
# building a network.
JUDGED_BY = {"sketchnet": ("score_overall", True), "pix2pix": ("depth_error", False), "segment": ("mask_iou", True)}
NETWORKS = tuple(JUDGED_BY)


class TrainingDataError(TreefarmError):
    """A folder given as training data is missing, empty, not a treefarm dataset, or unfit for the task."""


class MissingOutputError(TrainingDataError):
    """A dataset lacks a views-table output the task reads; the message names it and the spec that makes it."""


@dataclass(frozen=True)
class Task:
    """One network's training data, and which network learns it.

    name         : the task name (`farm train NAME`).
    inputs       : views-table outputs the network reads, first = its main input style.
    styles       : further input styles of the same view that augmentation swaps in (sketchnet: `sketch_hand`).
    targets      : views-table outputs the loss compares with (pix2pix, segment: a label map, tree > 0);
                   sketchnet's targets are the trees table's `params_json` and `species`.
    input_kind   : `trainers.preprocess` kind of the input ("sketch" 1 channel, "strokes" and "photo" 3 channels).
    input_size   : the network's input width and height, pixels.
    spec_name    : the shipped job spec `trainers/specs/<spec_name>.yaml` that makes this task's data.
    model_name   : the model's name in the registry.
    network      : the network family that learns it, one of `NETWORKS`.
    rigs         : view rigs (`render.rig` without ":jitter") the data must come from; empty: any rig.
    min_trees    : the fewest trees of the shipped spec (`trees` changed, nothing else) from which the split by tree
                   hash puts a tree in each of train, validation and test, for that count and every larger one
                   up to the spec's own (`tests/trainers/test_tasks.py` recomputes it; docs/training.md).
    recipe       : the training settings (`trainers.networks.TrainSettings` keys) of the shipped default model in
                   `models/NAME/`: `make models` and bench_train's budgeted run train with them.
    pix2pix only, about the target (`targets[0]`):
    channel_names  : its channels in order.
    depth_channels : those `trainers.pix2pix.masked_depth_error` scores.
    dense_channels : those supervised on every pixel (the others on the foreground only).
    mask_channel   : the channel that is the foreground mask (>= 0.5), or None: foreground where the first
                     channel is below 1 (the far plane, the background of a depth01 map).
    """

    name: str
    inputs: tuple[str, ...]
    styles: tuple[str, ...]
    targets: tuple[str, ...]
    input_kind: str
    input_size: int
    spec_name: str
    model_name: str
    network: str
    rigs: tuple[str, ...] = ()
    min_trees: int = 3
    recipe: Mapping[str, Any] = field(default_factory=dict, hash=False)
    channel_names: tuple[str, ...] = ()
    depth_channels: tuple[int, ...] = ()
    dense_channels: tuple[int, ...] = ()
    mask_channel: int | None = None

    def __post_init__(self) -> None:
        if self.network not in NETWORKS:
            raise TrainingDataError(f"task {self.name!r}: network {self.network!r} is unknown: allowed "
                                    f"{', '.join(NETWORKS)}")
        if self.network in ("pix2pix", "segment") and not (self.targets and self.channel_names):
            raise TrainingDataError(f"task {self.name!r}: a {self.network} task names its target output and the "
                                    f"target's channels")

    @property
    def out_channels(self) -> int:
        """Channels of a pix2pix or segment task's target (0 for sketchnet, whose targets are the trees table's)."""
        return len(self.channel_names)

    @property
    def primary_metric(self) -> str:
        """The held-out metric that judges a model of this task (its network family's)."""
        return JUDGED_BY[self.network][0]

    @property
    def higher_is_better(self) -> bool:
        return JUDGED_BY[self.network][1]

    @property
    def spec_path(self) -> Path:
        return SPECS_DIR / f"{self.spec_name}.yaml"

    @property
    def required_outputs(self) -> tuple[str, ...]:
        return self.inputs + self.styles + self.targets

    def _how_to_make(self) -> str:
        return (f"make it with `farm train {self.name} --print-data-spec > {self.spec_name}.yaml` and "
                f"`farm generate {self.spec_name}.yaml --out DIR`")

    def check_dataset(self, path: str) -> dict:
        """The manifest of the dataset at `path` when it holds every output this task needs from the rig it
        needs; a `TrainingDataError` (one line) for a missing, empty or non-dataset folder, a
        `MissingOutputError` naming the first missing output and the spec that makes it."""
        location = Location.resolve(str(path))
        if location.is_local:
            folder = Path(location.root)
            if not folder.exists():
                raise TrainingDataError(f"training data folder {path} does not exist: {self._how_to_make()}")
            if not folder.is_dir():
                raise TrainingDataError(f"training data {path} is a file, not a dataset folder: "
                                        f"{self._how_to_make()}")
            if not any(folder.iterdir()):
                raise TrainingDataError(f"training data folder {path} is empty, not a treefarm dataset: "
                                        f"{self._how_to_make()}")
        try:
            manifest = read_manifest(location)
        except DatasetError as exc:
            raise TrainingDataError(f"{exc}; for task {self.name}, {self._how_to_make()}") from None
        render = manifest.get("job", {}).get("render", {})
        stored = list(render.get("outputs", []))
        for output in self.required_outputs:
            if output not in stored:
                raise MissingOutputError(
                    f"dataset {path} lacks output {output!r}, which task {self.name} needs (it stores "
                    f"{', '.join(stored) or 'no views'}): the spec trainers/specs/{self.spec_name}.yaml makes it; "
                    f"{self._how_to_make()}")
        rig = str(render.get("rig", "")).split(":")[0]
        if self.rigs and rig not in self.rigs:
            raise TrainingDataError(f"dataset {path} was rendered with rig {render.get('rig')!r}; task {self.name} "
                                    f"needs rig {' or '.join(self.rigs)}: {self._how_to_make()}")
        if not manifest.get("counts", {}).get("views"):
            raise TrainingDataError(f"dataset {path} has no views (every tree failed?): `farm inspect {path}` "
                                    f"shows its failures")
        return manifest


# `recipe`: fixed epochs and seed 0 with no time limit, so `make models` takes the same steps on any machine; why
# these widths and schedules fit a CPU budget is in docs/training.md ("Default models").
TASKS: dict[str, Task] = {
    # TreeSketchNet (digest 4.2-4.3): a sketch to a Weber-Penn dictionary and its species, 224 px.
    "sketchnet": Task("sketchnet", inputs=("sketch_tsn",), styles=("sketch_hand",), targets=(),
                      input_kind="sketch", input_size=224, spec_name="sketchnet", model_name="sketchnet",
                      network="sketchnet", min_trees=49,
                      recipe={"width": 0.5, "depth": 0.5, "epochs": 4, "schedule": "cosine"}),
    # Seed 000's cGANs (digest 1.8-1.9): orthographic pairs at 256 px.
    # Edge sketch -> the renderers' "silhouette_envelope": the closed crown's smooth front depth01 (1 background),
    # gap and mask (what DepthMapCrown.from_silhouette reads; thresholded at 0.5, so learnt everywhere). The
    # per-leaf "silhouette" is not in an edge sketch (docs/training.md).
    "pix2pix-silhouette": Task("pix2pix-silhouette", inputs=("sketch_edges",), styles=(),
                               targets=("silhouette_envelope",), input_kind="sketch", input_size=256,
                               spec_name="pix2pix-silhouette", model_name="pix2pix-silhouette", network="pix2pix",
                               rigs=("two-view",), min_trees=35,
                               recipe={"width": 8, "batch_size": 4, "epochs": 5, "schedule": "cosine"},
                               channel_names=("front", "gap", "mask"), depth_channels=(0, 1), dense_channels=(2,),
                               mask_channel=2),
    # Colour strokes -> trunk depth01 (1 = no stroke); foreground = under a stroke.
    "pix2pix-trunk": Task("pix2pix-trunk", inputs=("trunk_strokes",), styles=(), targets=("trunk_depth",),
                          input_kind="strokes", input_size=256, spec_name="pix2pix-trunk",
                          model_name="pix2pix-trunk", network="pix2pix", rigs=("two-view",), min_trees=63,
                          recipe={"width": 16, "batch_size": 16, "epochs": 1, "schedule": "cosine"},
                          channel_names=("depth",), depth_channels=(0,)),
    # Issue 51's tree mask network: a photo-like render over a random backdrop -> the tree's pixels, 128 px (the
    # network is fully convolutional: photos run at their own aspect, `reconstruct.photo_masks`).
    "tree-mask": Task("tree-mask", inputs=("photo",), styles=(), targets=("photo_mask",), input_kind="photo",
                      input_size=128, spec_name="tree-mask", model_name="tree-mask", network="segment",
                      min_trees=40,
                      recipe={"width": 8, "batch_size": 16, "epochs": 6, "schedule": "cosine"},
                      channel_names=("tree",)),
}


def get_task(task: str | Task) -> Task:
    """A task by name, or the task itself; an unknown name raises TrainingDataError listing the known ones."""
    if isinstance(task, Task):
        return task
    if task not in TASKS:
        raise TrainingDataError(f"task {task!r} is unknown: allowed {', '.join(TASKS)}")
    return TASKS[task]


def print_data_spec(task: str | Task) -> str:
    """The YAML text of the job spec that makes the task's training data (`farm train TASK --print-data-spec`)."""
    return get_task(task).spec_path.read_text()
