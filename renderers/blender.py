"""Blender adapter: runs the Blender worker (renderers/blender_worker, in `.venv-blender`) on JSON job files.

In: a tree GLB and `Camera`s; out: photo PNGs, depth and mask PNGs and `cameras.json` in a folder.
"""
from __future__ import annotations

import json
import os
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from species.errors import TreefarmError

from .blender_worker import WORKER_SCRIPT
from .camera import Camera

__all__ = ["BlenderError", "BlenderPhotos", "blender_python", "blender_available", "run_job", "run_jobs",
           "render_photos", "glb_info", "load_view", "resize_camera", "time_cycles_view", "BLENDER_PYTHON_ENV",
           "DEFAULT_TIMEOUT_S"]

BLENDER_PYTHON_ENV = "TREEFARM_BLENDER_PYTHON"
REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_TIMEOUT_S = 1800.0
LOG_TAIL_LINES = 40


class BlenderError(TreefarmError):
    """The Blender environment is missing, or a Blender job was invalid, failed or timed out."""


def blender_python() -> Path:
    """The Python of the Blender environment: $TREEFARM_BLENDER_PYTHON, else `.venv-blender/bin/python`."""
    override = os.environ.get(BLENDER_PYTHON_ENV)
    path = Path(override) if override else REPO_ROOT / ".venv-blender" / "bin" / "python"
    if not (path.is_file() and os.access(path, os.X_OK)):
        where = f"${BLENDER_PYTHON_ENV} = {override!r}" if override else f"{path}"
        raise BlenderError(f"the Blender environment is missing ({where} is not an executable Python): "
                           f"run `make env` (or `make blender-env`) in {REPO_ROOT}")
    return path


def blender_available() -> bool:
    """True when the Blender environment exists (`blender_python()` finds its Python); callers that can do
    without Blender's outputs ask this instead of catching the error."""
    try:
        blender_python()
    except BlenderError:
        return False
    return True


def _tail(text: str, lines: int = LOG_TAIL_LINES) -> str:
    return "\n".join(text.strip().splitlines()[-lines:])


def run_job(kind: str, job: dict, out_dir: str | Path, timeout: float = DEFAULT_TIMEOUT_S) -> dict:
    """Run one worker job of `kind` with the keys in `job`; returns the worker's result dictionary.

    Writes out_dir/job.json, runs the worker, keeps its output in out_dir/blender.log, and reads
    out_dir/result.json. A failure raises BlenderError with the tail of Blender's log.
    """
    return run_jobs([(kind, job, out_dir)], timeout)[0]


def run_jobs(jobs: Sequence[tuple[str, dict, str | Path]], timeout: float = DEFAULT_TIMEOUT_S) -> list[dict]:
    """Run several (kind, job, out_dir) jobs in one Blender process (one start-up), in order.

    Each out_dir gets its job.json and result.json; the log of the whole run goes to the first out_dir's
    blender.log. Returns the result dictionaries; the first failure raises BlenderError (later jobs do not run).
    """
    if not jobs:
        raise BlenderError("run_jobs needs at least one (kind, job, out_dir) job; got none")
    paths = []
    for kind, job, out_dir in jobs:
        out_dir = Path(out_dir).resolve()
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "result.json").unlink(missing_ok=True)
        job_path = out_dir / "job.json"
        job_path.write_text(json.dumps({**job, "kind": kind, "out_dir": str(out_dir)}, indent=1))
        paths.append((kind, out_dir, job_path))
    log_path = paths[0][1] / "blender.log"
    command = [str(blender_python()), str(WORKER_SCRIPT)] + [str(p) for _, _, p in paths]
    try:
        proc = subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=paths[0][1])
    except subprocess.TimeoutExpired as exc:
        log = "".join(_text(part) for part in (exc.stdout, exc.stderr))
        log_path.write_text(log)
        raise BlenderError(f"Blender jobs in {paths[0][1]} ran past their {timeout:.0f} s timeout; "
                           f"last lines of the log:\n{_tail(log)}") from None
    log = proc.stdout + proc.stderr
    log_path.write_text(log)
    results = []
    for kind, out_dir, _ in paths:
        record = json.loads((out_dir / "result.json").read_text()) if (out_dir / "result.json").is_file() else {}
        if not record.get("ok"):
            what = "was invalid" if proc.returncode == 2 else f"failed (exit status {proc.returncode})"
            raise BlenderError(f"Blender job {kind!r} in {out_dir} {what}; last lines of its log:\n{_tail(log)}")
        results.append(record["result"])
    return results


def _text(output) -> str:
    return output.decode(errors="replace") if isinstance(output, bytes) else (output or "")


def _glb_path(glb: bytes | str | Path, folder: Path) -> Path:
    if isinstance(glb, (bytes, bytearray)):
        path = folder / "tree.glb"
        path.write_bytes(glb)
        return path
    path = Path(glb)
    if not path.is_file():
        raise BlenderError(f"glb {str(path)!r} does not exist: give GLB bytes or the path of a .glb file")
    return path.resolve()


def glb_info(glb: bytes | str | Path, timeout: float = 300.0) -> dict:
    """What Blender sees in a GLB: objects (name, part, vertices, triangles, materials), totals, bounds."""
    with tempfile.TemporaryDirectory(prefix="treefarm-blender-") as tmp:
        return run_job("info", {"glb": str(_glb_path(glb, Path(tmp)))}, tmp, timeout)


def resize_camera(camera: Camera, width: int, height: int) -> Camera:
    """The same camera for another image size (K scaled about pixel corners; same field of view)."""
    sx, sy = width / camera.width, height / camera.height
    K = camera.K.copy()
    K[0, 0], K[1, 1] = K[0, 0] * sx, K[1, 1] * sy
    # OpenCV pixel centres sit at j, so the image edge is at -0.5: scale about that edge.
    K[0, 2], K[1, 2] = (K[0, 2] + 0.5) * sx - 0.5, (K[1, 2] + 0.5) * sy - 0.5
    return Camera(int(width), int(height), K, camera.world_to_camera, camera.projection, camera.near,
                  camera.far, camera.ortho_half_width, camera.ortho_half_height, camera.name)


@dataclass(frozen=True)
class BlenderPhotos:
    """The files of a photos job, one entry per camera, and the cameras.json that records them.

    images, depths, masks : paths of the RGB photo, 16-bit depth PNG and part mask PNG of each view.
    depth_scales          : metres per depth PNG unit, per view.
    cameras               : the cameras as rendered; cameras_json: their file (our convention, OpenCV axes).
    render_seconds        : Cycles time per view (the first includes building the scene's BVH).
    setup_seconds         : import, materials and scene set-up, once per job.
    """

    images: list[Path]
    depths: list[Path]
    masks: list[Path]
    depth_scales: list[float]
    cameras: list[Camera]
    cameras_json: Path
    render_seconds: list[float]
    setup_seconds: float


def render_photos(glb: bytes | str | Path, cameras: Sequence[Camera], out_dir: str | Path, samples: int = 16,
                  size: int | None = None, timeout: float = DEFAULT_TIMEOUT_S, **settings) -> BlenderPhotos:
    """Photo-like Cycles (CPU) renders of a tree GLB from each camera, with depth and part masks.

    glb      : GLB bytes (`TreeMesh.to_glb()`) or a path.
    cameras  : `Camera`s in our convention; `size` (pixels) re-sizes them to size x size first.
    settings : more worker settings (seed, threads, denoise, sun_*, sky_strength, ground, alpha_cutout, ...;
               see renderers/blender_worker/photos.py DEFAULTS).
    Writes view_NNN.png, view_NNN_depth.png, view_NNN_mask.png and cameras.json into out_dir.
    """
    if not cameras:
        raise BlenderError("render_photos needs at least one camera; got none")
    if size is not None:
        if int(size) < 8:
            raise BlenderError(f"size {size} is too small: allowed 8 pixels or more")
        cameras = [resize_camera(c, int(size), int(size)) for c in cameras]
    cameras = list(cameras)
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    job = {"glb": str(_glb_path(glb, out_dir)), "cameras": [c.to_dict() for c in cameras],
           "samples": int(samples), **settings}
    result = run_job("photos", job, out_dir, timeout)
    views = result["views"]
    records = [{**camera.to_dict(), "image": v["image"], "depth": v["depth"], "mask": v["mask"],
                "depth_scale": v["depth_scale"]} for camera, v in zip(cameras, views)]
    cameras_json = out_dir / "cameras.json"
    cameras_json.write_text(json.dumps({"convention": "opencv", "world": "z-up metres",
                                        "depth": "metres = depth PNG value * depth_scale, 0 = sky",
                                        "mask": "0 background or ground, 1 bark, 2 leaves",
                                        "renderer": f"blender {result['blender_version']} cycles",
                                        "settings": result["settings"], "views": records}, indent=1))
    return BlenderPhotos(images=[out_dir / v["image"] for v in views],
                         depths=[out_dir / v["depth"] for v in views],
                         masks=[out_dir / v["mask"] for v in views],
                         depth_scales=[float(v["depth_scale"]) for v in views], cameras=cameras,
                         cameras_json=cameras_json, render_seconds=[v["render_seconds"] for v in views],
                         setup_seconds=float(result["setup_seconds"]))


def load_view(photos: BlenderPhotos, index: int) -> dict[str, np.ndarray]:
    """A view's arrays: "photo" (H, W, 3) uint8 sRGB, "depth" (H, W) float32 metres (0 = sky),
    "mask" (H, W) uint8 (0 background or ground, 1 bark, 2 leaves)."""
    from PIL import Image

    depth = np.asarray(Image.open(photos.depths[index]), dtype=np.float64) * photos.depth_scales[index]
    return {"photo": np.asarray(Image.open(photos.images[index]).convert("RGB")),
            "depth": depth.astype(np.float32),
            "mask": np.asarray(Image.open(photos.masks[index]), dtype=np.uint8)}


def time_cycles_view(size: int, glb: bytes | str | Path, cameras: Sequence[Camera], samples: int = 16,
                     threads: int = 1) -> float:
    """Seconds of Cycles (CPU, `threads` threads) per view at size x size, averaged over `cameras`.

    Counts each render call (the first one builds the BVH); not the worker's start, GLB import or set-up.
    For the render benchmark's comparison column.
    """
    with tempfile.TemporaryDirectory(prefix="treefarm-cycles-") as tmp:
        photos = render_photos(glb, cameras, tmp, samples=samples, size=size, threads=threads)
        return float(np.mean(photos.render_seconds))
