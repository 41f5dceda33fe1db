"""treefarm's networks and their training: the tasks, training data over dataset shards, the loops on Ray
Train, the MLflow model registry and the predictors that reconstruction runs.

Entry points (each imported on first use, see below):
- tasks: `TASKS`, `get_task(name)`, `print_data_spec(task)` (`trainers.tasks`);
- data: `open_data(task, folders)`, `split_part(key)` (`trainers.data`);
- training: `TrainSettings` (`trainers.networks`), `train(task, data, ...)` (`trainers.training`), `retrain(task,
  data, registry, ...)` and `register_result(registry, result)` (`trainers.models`);
- registry: `open_registry(models)`, `Registry` (`trainers.registry`);
- inference: `load(name, models)` giving a `Predictor` (`trainers.models`: ONNX Runtime, no torch), and the module
  `trainers.preprocess` (a drawing to a network input, as in training).
"""
from __future__ import annotations

import importlib

# Public name -> the module defining it, imported when the name is first read (PEP 562): most of them import torch
# (or MLflow), which neither the `farm` command line's start-up nor an inference-only caller should pay for.
_HOMES = {
    "TASKS": "trainers.tasks", "Task": "trainers.tasks", "get_task": "trainers.tasks",
    "print_data_spec": "trainers.tasks", "TrainingDataError": "trainers.tasks",
    "open_data": "trainers.data", "split_part": "trainers.data", "Split": "trainers.data",
    "TrainSettings": "trainers.networks", "SettingsError": "trainers.networks",
    "train": "trainers.training", "TrainResult": "trainers.training", "TrainingError": "trainers.training",
    "retrain": "trainers.models", "register_result": "trainers.models", "load": "trainers.models",
    "Predictor": "trainers.models",
    "open_registry": "trainers.registry", "Registry": "trainers.registry", "RegistryError": "trainers.registry",
}

__all__ = list(_HOMES)


def __getattr__(name: str):
    if name not in _HOMES:
        raise AttributeError(f"module 'trainers' has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
