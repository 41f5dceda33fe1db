"""A photo tree seen from the photos' own cameras (issue 51): the registered cameras in the frame the tree's GLB is
written in (NAME.cameras.json, in the convention a photo folder's cameras.json is read in, so the same photos can
be run again at those poses), and each photo with the tree's outline drawn over it (NAME.outlines.png), with the
share of the photo's tree mask that the outline covers.

In: a `Reconstruction` of method "photos" (its maps "cameras": each registered photo's name and `PinholeView` in
the scan frame, and, for the hull shape, "masks") and the photos' folder. The outline is the result's silhouette
rendered offscreen (`renderers.ViewRenderer.silhouette_masks`) from each camera, its gaps closed as the scorer's
crown outlines are; coverage compares it with the photo's tree mask closed the same way.
"""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from renderers import ViewRenderer, write_contact_sheet
from renderers.camera import Camera

from .result import Reconstruction
from .scoring import crowns

__all__ = ["registered_cameras", "cameras_document", "outlines", "outline_views", "write_outlines", "OUTLINE_SIDE"]

OUTLINE_SIDE = 384        # px: each photo's longer side on the outlines sheet
OUTLINE_COLOUR = (255, 40, 40)


def registered_cameras(result: Reconstruction) -> list[Camera]:
    """Each registered photo's perspective camera, named by its photo, in the frame the result's files are
    written in (frame "base": the tree's base at the origin; "scan": the photos' upright metric frame)."""
    views = result.maps.get("cameras")
    if not views:
        raise ValueError(f"a {result.method} reconstruction carries no registered cameras: they are the photos "
                         "method's")
    scan = result.scan
    rotation, shift = scan.transform[:3, :3], scan.transform[:3, 3]
    cameras = []
    for name, view in views:
        if scan.frame == "base":
            # x_scan = R x_base + t, so the camera's world-to-camera rotation gains R and its centre moves back
            view = type(view)(view.rotation @ rotation, rotation.T @ (view.centre - shift), view.focal,
                              view.principal, view.size)
        cameras.append(view.to_camera(name=name))
    return cameras


def cameras_document(result: Reconstruction) -> dict:
    """NAME.cameras.json's content: `registered_cameras` as a photo folder's cameras.json lists them."""
    return {"convention": "opencv", "world": f"z-up metres, the tree's {result.scan.frame} frame (its GLB's)",
            "views": [{**camera.to_dict(), "image": camera.name} for camera in registered_cameras(result)]}


def outlines(result: Reconstruction, renderer: ViewRenderer) -> list[tuple[Camera, np.ndarray]]:
    """Each registered photo's camera (`registered_cameras`) and the result's outline in it: its silhouette, gaps
    closed as the scorer's crown outlines are, (H, W) bool at the photo's size."""
    mesh = result.mesh if result.scan.frame == "base" else result.in_scan_frame()[1]
    return [(camera, crowns(renderer.silhouette_masks(mesh, [camera]))[0]) for camera in registered_cameras(result)]


def outline_views(result: Reconstruction, folder: str | Path, renderer: ViewRenderer
                  ) -> list[tuple[str, np.ndarray, float | None]]:
    """(photo name, the photo shrunk to OUTLINE_SIDE on its longer side with the result's outline drawn over it
    (letterboxed to a square),
    the share of the photo's tree mask inside the outline or None without masks) for each registered photo."""
    masks = result.maps.get("masks")
    out = []
    for index, (camera, outline) in enumerate(outlines(result, renderer)):
        with Image.open(Path(folder) / camera.name) as photo:
            image = np.asarray(photo.convert("RGB"))
        covered = None
        if masks is not None:
            tree = crowns(np.asarray(masks[index], bool)[None])[0]
            covered = float((tree & outline).sum() / tree.sum()) if tree.any() else None
        scale = OUTLINE_SIDE / max(image.shape[:2])
        size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
        small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        edge = cv2.resize(outline.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
        contours, _ = cv2.findContours(edge, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(small, contours, -1, OUTLINE_COLOUR, 2, cv2.LINE_AA)
        # letterboxed: the contact sheet's cells are square
        square = np.full((OUTLINE_SIDE, OUTLINE_SIDE, 3), 255, np.uint8)
        top, left = (OUTLINE_SIDE - size[1]) // 2, (OUTLINE_SIDE - size[0]) // 2
        square[top:top + size[1], left:left + size[0]] = small
        out.append((camera.name, square, covered))
    return out


def write_outlines(result: Reconstruction, folder: str | Path, cameras_json: str | Path,
                   outlines_png: str | Path) -> list[float | None]:
    """Write NAME.cameras.json and NAME.outlines.png (module docstring); returns each photo's covered share."""
    renderer = ViewRenderer(OUTLINE_SIDE)
    try:
        views = outline_views(result, folder, renderer)
    finally:
        renderer.close()
    cells = [(name if covered is None else f"{name}: {covered:.0%} covered", image) for name, image, covered in views]
    per_row = int(np.ceil(np.sqrt(len(cells))))
    rows = [("outline from the photo's camera", cells[k:k + per_row]) for k in range(0, len(cells), per_row)]
    write_contact_sheet(outlines_png, rows, cell=OUTLINE_SIDE)
    Path(cameras_json).write_text(json.dumps(cameras_document(result), indent=1))
    return [covered for _, _, covered in views]
