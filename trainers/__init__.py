"""treefarm's networks and their training: the tasks, training data over dataset shards, the loops on Ray
Train, the MLflow model registry and the predictors that reconstruction runs.

Entry points:
- tasks: `TASKS`, `get_task(name)`, `print_data_spec(task)` (`trainers.tasks`);
- registry: `open_registry(models)`, `Registry` (`trainers.registry`: MLflow loads when a registry is opened);
- data: `open_data(task, folders)`, `split_part(key)` (`trainers.data`);
- training: `TrainSettings` (`trainers.networks`), `train(task, data, ...)` (`trainers.training`), `retrain(task,
  data, registry, ...)` and `register_result(registry, result)` (`trainers.models`);
- inference: `load(name, models)` giving a `Predictor` (`trainers.models`: ONNX Runtime, no torch), and the module
  `trainers.preprocess` (a drawing to a network input, as in training).
The data, training and model names are imported on first use (PEP 562): their modules import torch.
"""
from __future__ import annotations

from .registry import Registry, RegistryError, open_registry
from .tasks import TASKS, Task, TrainingDataError, get_task, print_data_spec

__all__ = ["TASKS", "Task", "get_task", "print_data_spec", "TrainingDataError",
           "open_registry", "Registry", "RegistryError",
           "open_data", "split_part", "Split", "TrainSettings", "SettingsError",
           "train", "TrainResult", "TrainingError", "retrain", "register_result", "load", "Predictor"]


def __getattr__(name: str):
    # Imported here, not above: these modules import torch, which `import trainers` (the farm CLI, inference
    # through ONNX Runtime) should not pay for.
    if name in ("open_data", "split_part", "Split"):
        from . import data as home
    elif name in ("TrainSettings", "SettingsError"):
        from . import networks as home
    elif name in ("train", "TrainResult", "TrainingError"):
        from . import training as home
    elif name in ("retrain", "register_result", "load", "Predictor"):
        from . import models as home
    else:
        raise AttributeError(f"module 'trainers' has no attribute {name!r}")
    return getattr(home, name)
