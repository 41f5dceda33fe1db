"""Species presets: parameter templates split into fixed values and sampled ranges, and the sampler.

A preset names its generator; `sample(preset, rng)` draws a complete, valid parameter dictionary whose
`seed` key seeds every further random choice of growth, so the dictionary alone rebuilds the tree.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .errors import TreefarmError

__all__ = ["Preset", "Uniform", "IntRange", "Choice", "Jitter", "register_presets", "get_preset",
           "list_presets", "sample", "PresetError"]


class PresetError(TreefarmError):
    """An unknown preset name or a malformed template."""


# ---------------------------------------------------------------- range specs (what "unfixed" means)
@dataclass(frozen=True)
class Uniform:
    """A float drawn uniformly from [low, high]; lists give one range per element."""

    low: float | list[float]
    high: float | list[float]

    def draw(self, rng: np.random.Generator) -> Any:
        lo, hi = np.asarray(self.low, float), np.asarray(self.high, float)
        value = np.asarray(rng.uniform(lo, hi))
        return value.tolist() if value.ndim else float(value)


@dataclass(frozen=True)
class IntRange:
    """An integer drawn uniformly from [low, high] inclusive."""

    low: int
    high: int

    def draw(self, rng: np.random.Generator) -> int:
        return int(rng.integers(self.low, self.high + 1))


@dataclass(frozen=True)
class Choice:
    """One of a list of values, optionally weighted."""

    options: tuple
    weights: tuple | None = None

    def draw(self, rng: np.random.Generator) -> Any:
        p = None if self.weights is None else np.asarray(self.weights, float) / np.sum(self.weights)
        return self.options[int(rng.choice(len(self.options), p=p))]


@dataclass(frozen=True)
class Jitter:
    """A base value (scalar or list) scaled by U(1 - rel, 1 + rel) and shifted by U(-add, add), clipped.

    TreeSketchNet varies its unfixed parameters relative to their order of magnitude; this is that rule.
    """

    base: float | list[float]
    rel: float = 0.25
    add: float = 0.0
    low: float | None = None
    high: float | None = None
    integer: bool = False

    def draw(self, rng: np.random.Generator) -> Any:
        base = np.asarray(self.base, float)
        value = base * rng.uniform(1 - self.rel, 1 + self.rel, base.shape)
        if self.add:
            value = value + rng.uniform(-self.add, self.add, base.shape)
        if self.low is not None or self.high is not None:
            value = np.clip(value, self.low, self.high)
        if self.integer:
            value = np.rint(value).astype(int)
        return value.tolist() if value.ndim else (int(value) if self.integer else float(value))


# ---------------------------------------------------------------- presets
@dataclass(frozen=True)
class Preset:
    """A species template.

    name        : unique preset name (`farm tree --species NAME`).
    generator   : `weber_penn`, `colonization` or `lsystem`.
    description : one line for `farm species`.
    fixed       : keys constant within the species (they identify it).
    ranges      : keys drawn per tree: a range spec (Uniform, IntRange, Choice, Jitter) or a callable
                  `f(rng, params_so_far) -> value` for draws that depend on other keys.
    """

    name: str
    generator: str
    description: str
    fixed: dict[str, Any]
    ranges: dict[str, Any] = field(default_factory=dict)

    def sample(self, rng: np.random.Generator) -> dict:
        params: dict[str, Any] = {"generator": self.generator, "species": self.name}
        params.update(_copy_json(self.fixed))
        for key in sorted(self.ranges):  # sorted: draw order must not depend on dict construction
            spec = self.ranges[key]
            params[key] = spec(rng, params) if callable(spec) and not hasattr(spec, "draw") else spec.draw(rng)
        params["seed"] = int(rng.integers(0, 2**31 - 1))
        return params

    def base_params(self) -> dict:
        """The template's fixed values with every range at its centre: a typical member of the species."""
        params: dict[str, Any] = {"generator": self.generator, "species": self.name}
        params.update(_copy_json(self.fixed))
        for key, spec in self.ranges.items():
            if isinstance(spec, Jitter):
                params[key] = spec.base
            elif isinstance(spec, Uniform):
                centre = (np.asarray(spec.low, float) + np.asarray(spec.high, float)) / 2
                params[key] = centre.tolist() if centre.ndim else float(centre)
            elif isinstance(spec, IntRange):
                params[key] = (spec.low + spec.high) // 2
            elif isinstance(spec, Choice):
                params[key] = spec.options[0]
        params["seed"] = 0
        return params


def _copy_json(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _copy_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_copy_json(v) for v in value]
    return value


_REGISTRY: dict[str, Preset] = {}
_LOADERS: list[Callable[[], list[Preset]]] = []


def register_presets(loader: Callable[[], list[Preset]]) -> None:
    """Add a generator's presets, loaded lazily on first use (keeps `import species` cheap)."""
    _LOADERS.append(loader)


def _load_all() -> dict[str, Preset]:
    while _LOADERS:
        for preset in _LOADERS.pop(0)():
            if preset.name in _REGISTRY:
                raise PresetError(f"preset {preset.name!r} is defined twice")
            _REGISTRY[preset.name] = preset
    return _REGISTRY


def list_presets(generator: str | None = None) -> list[Preset]:
    """All presets (of one generator if given), sorted by generator then name."""
    presets = _load_all().values()
    if generator is not None:
        presets = [p for p in presets if p.generator == generator]
    return sorted(presets, key=lambda p: (p.generator != "weber_penn", p.generator, p.name))


def get_preset(name: str | Preset) -> Preset:
    if isinstance(name, Preset):
        return name
    registry = _load_all()
    if name not in registry:
        raise PresetError(f"unknown species {name!r}; known: {', '.join(sorted(registry))}")
    return registry[name]


def sample(preset: str | Preset, rng: np.random.Generator) -> dict:
    """Draw one parameter dictionary of a species with `rng`; it validates and grows as it is."""
    return get_preset(preset).sample(rng)
