"""treefarm reconstruct: trees from sketches, point clouds and photos, and the metrics that judge them.

Methods (`reconstruct.methods.METHODS`, the one registry; docs/reconstruct.md lists them): `from_params` (seed 004:
TreeSketchNet's dictionary grown by the Weber-Penn generator), `from_sketch` (seed 000: depth-guided growth from a
silhouette sketch and trunk strokes through the two depth networks; `from_maps` from their maps), `two_view`
(seed 001: two orthogonal drawings, no network), `from_cloud` (AdTree's skeleton and seed 003's completion from a
scan) and `from_photos` (pycolmap SfM, then `from_cloud`). Each returns a `Reconstruction`: the `Skeleton`, the
`TreeMesh`, the dictionary it grew with (or None), stage timings and intermediate maps, and for a scan its
`ScanRecord`. `reconstruct.metrics` scores a reconstruction against its ground truth. The submodules keep their
names: `from reconstruct.trunk_tracing import trace_trunk`.

A name below is imported from its module on first use: the methods pull in scipy, OpenCV, torch and pycolmap, and
the command line reads the registry (`reconstruct.methods`) at start-up.
"""
from __future__ import annotations

import importlib
import sys
import types

# public name -> the submodule that defines it
_HOMES = {
    "METHODS": "methods", "Method": "methods", "Input": "methods", "Rendered": "methods", "RunOptions": "methods",
    "MethodError": "methods", "get_method": "methods", "Reconstruction": "result", "ScanRecord": "result",
    "from_params": "from_params", "from_sketch": "from_sketch", "from_maps": "from_sketch", "SketchError": "from_sketch",
    "two_view": "two_view", "TwoViewError": "two_view", "from_cloud": "from_cloud", "from_photos": "from_photos",
    "read_cloud": "clouds", "PointCloud": "clouds", "CloudError": "clouds", "MetricError": "metrics",
    "InputImageError": "networks",
}

__all__ = list(_HOMES)


def __getattr__(name: str):
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOMES))


class _Package(types.ModuleType):
    """The package's module type. Once a submodule is loaded, the import system binds it to the package's attribute
    of its name; five methods share their module's name (`from_cloud`, ...), and there the name stays the method."""

    def __setattr__(self, name: str, value) -> None:
        if isinstance(value, types.ModuleType) and _HOMES.get(name) == name:
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
