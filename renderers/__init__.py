"""treefarm renderers: cameras and view rigs, depth/mask/silhouette maps, trunk strokes, sketch styles, contact sheets.

Public surface: `ViewRenderer(size).render(tree, skeleton, rig, outputs, rng) -> list[RenderedView]`, the same in
given cameras `.render_cameras(tree, skeleton, cameras, outputs, rng)`, `.silhouette_masks(tree, cameras) -> (V, H,
W) bool`, `Camera`, `make_rig`/`RIGS` (rig "two-view:shared": front and side at one pixel scale), `OUTPUTS` (name ->
`Output`: how a view makes it, its dtype, whether metric or labels; `FLOAT_OUTPUTS`/`METRIC_MAPS`/`LABEL_MAPS`
follow from it)/`DEFAULT_OUTPUTS`, `PALETTE`, `write_contact_sheet`. Output arrays (per view):
"depth" (H, W) float32 metres, 0 background; "depth01" (H, W) float32 in [0, 1], 1 background/far;
"mask" (H, W) uint8 0 background / 1 bark / 2 leaves; "order" (H, W) uint8 branch order + 1 on bark, 0 elsewhere;
"normals" (H, W, 3) uint8 camera-frame normals; "silhouette" (H, W, 3) float32 (front depth01, front-to-back gap,
mask); "silhouette_envelope" the same of the closed crown with smooth front and back; "depth_back" (H, W)
float32 metres of the farthest surface; "trunk_strokes" (H, W, 3) uint8;
"trunk_depth" (H, W) float32 in [0, 1], 1 = no stroke; "sketch_*" (H, W) uint8, black lines on white.
"""
from __future__ import annotations

from .camera import RIGS, Camera, CameraError, make_rig, parse_rig, rig_parts
from .contact_sheet import views_sheet_rows, viewable, write_contact_sheet
from .strokes import PALETTE, main_branches
from .views import (DEFAULT_OUTPUTS, FLOAT_OUTPUTS, LABEL_MAPS, METRIC_MAPS, OUTPUTS, Output, OutputError,
                    RenderedView, ViewRenderer, check_outputs)

__all__ = ["ViewRenderer", "RenderedView", "Camera", "CameraError", "RIGS", "make_rig", "parse_rig", "rig_parts",
           "OUTPUTS", "Output", "FLOAT_OUTPUTS", "METRIC_MAPS", "LABEL_MAPS", "DEFAULT_OUTPUTS", "OutputError",
           "check_outputs", "PALETTE", "main_branches", "write_contact_sheet", "viewable", "views_sheet_rows"]
