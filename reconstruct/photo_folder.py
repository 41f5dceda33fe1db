"""What a folder of photos is, before SfM: its photos (IMAGE_SUFFIXES, at least MIN_PHOTOS), and the error of a
folder that cannot become points (PhotoError), and the camera height that scales photos with no other scale
(CAMERA_HEIGHT_M). The poses of its `cameras.json` are `reconstruct.sfm.known_cameras`.

Kept apart from `reconstruct.sfm` so the command line tells a photo folder, and refuses a bad one, without
importing pycolmap.
"""
from __future__ import annotations

from pathlib import Path

from .clouds import CloudError

__all__ = ["PhotoError", "IMAGE_SUFFIXES", "MIN_PHOTOS", "CAMERA_HEIGHT_M", "photo_names", "check_readable"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
MIN_PHOTOS = 3          # fewer cannot triangulate a point seen from three directions
CAMERA_HEIGHT_M = 1.5   # a handheld phone's height above the ground: the photos' scale when no other is given


class PhotoError(CloudError):
    """A photo folder that SfM cannot turn into points; the message names the value and what is allowed."""


def photo_names(folder: str | Path) -> list[str]:
    """The sorted names of the photos directly in `folder`; PhotoError for a missing folder or too few photos."""
    folder = Path(folder)
    if not folder.is_dir():
        raise PhotoError(f"{folder} is not a folder: allowed a folder of photos ({', '.join(IMAGE_SUFFIXES)})")
    names = sorted(p.name for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
                   and not p.stem.endswith(("_depth", "_mask")))
    if len(names) < MIN_PHOTOS:
        raise PhotoError(f"{folder} holds {len(names)} photo(s): allowed at least {MIN_PHOTOS} "
                         f"({', '.join(IMAGE_SUFFIXES)})")
    return names


def check_readable(folder: str | Path, names: list[str]) -> None:
    """PhotoError naming the first of `names` that is not an image a reader can open (its header only is read),
    so a broken file is refused before SfM spends its time on the others."""
    # Pillow here, not at the top: the method registry and the command line read this module's defaults, and a
    # point cloud's run loads no image library
    from PIL import Image, UnidentifiedImageError

    for name in names:
        try:
            with Image.open(Path(folder) / name) as image:
                image.size
        except (OSError, UnidentifiedImageError, ValueError) as error:
            raise PhotoError(f"{Path(folder) / name} cannot be read as an image ({error}): allowed photos "
                             f"({', '.join(IMAGE_SUFFIXES)})") from None
