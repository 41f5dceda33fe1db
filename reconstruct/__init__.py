"""treefarm reconstruct: trees from sketches, point clouds and photos, and the metrics that judge them.

Methods: `from_sketch` (seed 000: depth-guided growth from a silhouette sketch and trunk strokes through the two
depth networks; `from_maps` from their maps), `from_params` (seed 004: TreeSketchNet's dictionary grown by the
Weber-Penn generator), `two_view` (seed 001: two orthogonal drawings, no network), `from_cloud` (AdTree's skeleton
and seed 003's completion from a scan) and `from_photos` (pycolmap SfM, then `from_cloud`); `reconstruct.metrics` scores a
reconstruction against its ground truth. Each method returns the `Skeleton`, the `TreeMesh` and a report of stage
timings and intermediate maps. The submodules keep their names: `from reconstruct.trunk_tracing import trace_trunk`.
"""
from .clouds import CloudError, PointCloud, read_cloud
from .from_cloud import CloudReconstruction, from_cloud
from .from_photos import from_photos
from .from_params import ParamsReconstruction, from_params
from .from_sketch import SketchError, SketchReconstruction, from_maps, from_sketch
from .metrics import MetricError
from .networks import InputImageError
from .two_view import TwoViewError, TwoViewResult, two_view

__all__ = ["from_cloud", "CloudReconstruction", "from_photos", "read_cloud", "PointCloud", "CloudError", "from_sketch", "from_maps", "SketchReconstruction", "SketchError", "from_params", "ParamsReconstruction",
           "two_view", "TwoViewResult", "TwoViewError", "MetricError", "InputImageError"]
