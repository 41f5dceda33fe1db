"""One `grow` for every growth model: dispatch on the dictionary's `generator` key.

A dictionary without a generator key is Weber-Penn, so Sapling dictionaries load unchanged. A dictionary with no
key that describes a tree (`{}`, or only `generator`) is refused: it would grow the generator's default tree.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from .errors import ParameterError, TreeTooLargeError
from .meshing import build_mesh
from .skeleton import Skeleton
from .tree_mesh import TreeMesh

__all__ = ["grow", "rebuild", "Generator", "GENERATORS", "generator_of", "rng_for", "check_describes_a_tree",
           "RECORD_KEYS"]


@dataclass(frozen=True)
class Generator:
    """A growth model, named by modules so that `import species` loads none of them.

    grow    : "module:function" taking (params, rng) and returning a Skeleton.
    presets : module whose `PRESETS` (a list of `species.Preset`) are the generator's species, loaded on first use.
    """

    grow: str
    presets: str


# The generator registry: a parameter dictionary's `generator` key names one; adding a generator is one entry.
GENERATORS: dict[str, Generator] = {
    "weber_penn": Generator("species.weber_penn.generator:grow", "species.weber_penn.presets"),
    "colonization": Generator("species.colonization.generator:grow", "species.colonization.presets"),
    "lsystem": Generator("species.lsystem.generator:grow", "species.lsystem.presets"),
}


def generator_of(params: dict) -> str:
    if not isinstance(params, dict):
        raise ParameterError("params", type(params).__name__, "a JSON object (dict) of parameters")
    name = params.get("generator", "weber_penn")
    if name not in GENERATORS:
        raise ParameterError("generator", name, f"one of {sorted(GENERATORS)}")
    return name


# Keys that route, label or seed a dictionary: none says what tree to grow, so a dictionary of only these grows
# the generator's default tree, which nobody asks for by writing `{}` or `{"generator": ...}`.
RECORD_KEYS = ("generator", "species", "seed", "draws", "name")


def check_describes_a_tree(params: dict, ignored: Iterable[str] = ()) -> None:
    """Raise ParameterError when `params` holds no key beside RECORD_KEYS and the `ignored` ones (keys its
    generator accepts and grows nothing from)."""
    if set(params) - set(RECORD_KEYS) - set(ignored):
        return
    beside = [*RECORD_KEYS, *(key for key in params if key in set(ignored))]
    raise ParameterError("params", params, f"a dictionary with at least one {generator_of(params)} parameter "
                         f"beside {', '.join(beside)} (`farm tree --species NAME --save-params` writes one)")


def _grower(name: str) -> Callable[[dict, np.random.Generator], Skeleton]:
    module, function = GENERATORS[name].grow.split(":")
    return getattr(importlib.import_module(module), function)


def grow(params: dict, rng: np.random.Generator) -> Skeleton:
    """Grow the tree a parameter dictionary describes. Same dictionary and same rng state, same skeleton."""
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    name = generator_of(params)
    check_describes_a_tree(params)
    return _grower(name)(params, rng)


def rng_for(params: dict) -> np.random.Generator:
    """The generator a dictionary's own `seed` key defines: how a dictionary alone rebuilds its tree."""
    seed = params.get("seed", 0) if isinstance(params, dict) else 0
    if isinstance(seed, bool) or not isinstance(seed, (int, float)) or seed < 0 or int(seed) != seed:
        raise ParameterError("seed", seed, "a non-negative integer")
    return np.random.default_rng(int(seed))


def rebuild(params: dict, name: str | None = None, max_nodes: int | None = None) -> tuple[Skeleton, TreeMesh]:
    """A dictionary's own tree: grown with `rng_for(params)` and meshed; `name` names the mesh (and its files).

    With `max_nodes`, a skeleton of more nodes raises TreeTooLargeError before meshing, so one runaway draw
    costs its growth and not a mesh of millions of triangles.
    """
    skeleton = grow(params, rng_for(params))
    if max_nodes is not None and skeleton.n_nodes > max_nodes:
        raise TreeTooLargeError(f"skeleton has {skeleton.n_nodes} nodes; allowed max_nodes = {max_nodes}")
    return skeleton, build_mesh(skeleton, params if name is None else {**params, "name": name})
