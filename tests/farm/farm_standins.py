"""Stand-in tree builders for the farm tests: numpy-only trees and views with the real builder's interface.

They make the pipeline tests fast and independent of growth models and GL; `KillOnce` kills its worker process;
a `memory_hog` tree allocates 3 GiB; `refusing_chain` and `broken_chain` fail in the worker with a user's error and with a bug.
"""
from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from farm.jobs import parse_spec
from farm.tree_chain import BuiltTree, stage_rngs, tree_seed
from species.errors import ParameterError
from species.skeleton import Skeleton

SPECIES = ("standin_a", "standin_b", "broken", "memory_hog", "standin_with_a_long_preset_name")
# What a `memory_hog` tree allocates (and touches) as it grows: more than a 1 GiB worker limit allows.
HOG_BYTES = 3 * 2**30
OUTPUTS = ("depth", "mask", "silhouette", "sketch_tsn")
SIZE = 32
# The user's error `refusing_chain` raises in its worker, as the CLI should print it.
REFUSAL = ParameterError("standin.lens_mm", 0.0, "a number > 0")


def standin_spec(**fields):
    """A small valid spec over the stand-in species (5 trees, shards of 2, 2 views each)."""
    raw = {"name": "standin", "seed": 7, "species": {"standin_a": 3, "standin_b": 2}, "shard_size": 2,
           "render": {"rig": "two-view", "size": SIZE, "outputs": list(OUTPUTS)}, "store_glb": False}
    raw.update(fields)
    return parse_spec(raw, known_species=SPECIES, known_outputs=OUTPUTS)


class _Camera:
    def __init__(self, index: int):
        self.index = index

    def to_dict(self) -> dict:
        return {"projection": "orthographic", "width": SIZE, "height": SIZE, "azimuth_deg": 90.0 * self.index}


class StandinChain:
    """Deterministic fake trees: a vertical chain of nodes, 2 views of noise images; species 'broken' raises."""

    def __init__(self, spec):
        self.spec = spec

    def __call__(self, species_name: str, seed: int, timer) -> BuiltTree:
        sample_rng, render_rng = stage_rngs(seed)
        with timer.stage("sample"):
            params = {"generator": "standin", "species": species_name,
                      "height": float(sample_rng.uniform(1.0, 3.0)), "seed": int(sample_rng.integers(0, 2**31 - 1))}
        with timer.stage("grow"):
            if species_name == "broken":
                raise ValueError(f"stand-in growth refuses species {species_name!r}")
            if species_name == "memory_hog":
                np.ones(HOG_BYTES // 8).sum()
            rng = np.random.default_rng(params["seed"])
            n = 6
            positions = np.zeros((n, 3))
            positions[:, 2] = np.linspace(0.0, params["height"], n)
            positions[1:, :2] = rng.normal(0.0, 0.05, (n - 1, 2))
            skeleton = Skeleton(positions, np.arange(-1, n - 1), np.linspace(0.1, 0.02, n), np.zeros(n))
        with timer.stage("render"):
            views = []
            for index in range(2):
                depth = render_rng.uniform(2.0, 4.0, (SIZE, SIZE)).astype(np.float32)
                depth[:, : SIZE // 4] = 0.0
                images = {"depth": depth, "mask": render_rng.integers(0, 3, (SIZE, SIZE), dtype=np.uint8),
                          "silhouette": render_rng.uniform(0, 1, (SIZE, SIZE, 3)).astype(np.float32),
                          "sketch_tsn": render_rng.integers(0, 256, (SIZE, SIZE), dtype=np.uint8)}
                views.append(SimpleNamespace(index=index, name=("front", "side")[index], camera=_Camera(index),
                                             images={k: images[k] for k in self.spec.render.outputs}))
        return BuiltTree(params=params, skeleton=skeleton, mesh=None, views=views)


class SlowChain(StandinChain):
    """Stand-in trees that take 0.6 s each: long enough for a driver to see each one land."""

    def __call__(self, species_name: str, seed: int, timer) -> BuiltTree:
        time.sleep(0.6)
        return super().__call__(species_name, seed, timer)


class KillOnce:
    """Wraps a builder; the first time any process reaches tree `at_index` it kills itself (SIGKILL).

    The flag file marks that the kill happened, so Ray's retry of the shard then runs normally.
    """

    def __init__(self, spec, inner_factory, flag: str, at_index: int):
        self.inner = inner_factory(spec)
        self.flag, self.kill_seed = Path(flag), tree_seed(spec.seed, at_index)

    def __call__(self, species_name: str, seed: int, timer) -> BuiltTree:
        if seed == self.kill_seed and not self.flag.exists():
            self.flag.write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
        return self.inner(species_name, seed, timer)


def refusing_chain(spec):
    """A builder factory that refuses the job in the worker with a user's error (a ParameterError)."""
    raise ParameterError(REFUSAL.key, REFUSAL.value, REFUSAL.allowed)


def broken_chain(spec):
    """A builder factory that fails in the worker with a bug (a KeyError)."""
    raise KeyError("standin_lookup_table")
