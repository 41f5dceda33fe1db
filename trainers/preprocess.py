"""The one preprocessing step of every network input, in training and at inference: a drawing to a network tensor.

In: an image array (uint8 or float, greyscale, RGB or RGBA, any size): our renders, a scan or a tablet drawing.
Out: float32 (C, size, size), ink in [0, 1] on a paper of 0, cropped to the drawing, as `sketch_to_input` encodes
the renders (`trainers.pix2pix`): so a hand drawing reaches the network the way the training sketches did.

Steps (all vectorised, OpenCV for morphology and resizing):
1. Paper and ink levels: an RGBA image is laid over white paper by its alpha. The paper is the median of the
   image's border ring (a drawing sits inside its page; the ring is robust to drawings denser than half the page).
   A dark paper (light strokes: chalk, a dark tablet canvas, an inverted render) is inverted (sketch) or its
   paper colour replaced by white (colour strokes, whose hues carry branch identity and must not be inverted).
   Levels are stretched so the paper is exactly white and the typical dark stroke exactly ink (scans are grey).
2. The drawing: ink pixels (at least half way from paper to ink), ignoring specks smaller than SPECK_SHARE of
   the image (dust on a scan). None at all raises `PreprocessError` (a blank image). A sketch's ground line
   (`ground_line`: a long stroke under the tree reaching out beyond it) is left out: the renders have no ground.
3. Crop to the drawing's bounding box plus MARGIN of its larger side on each side, as a square centred on the
   box (paper outside the image), so the same drawing small in a corner or filling its page comes out alike.
4. Strokes that would come out thinner than MIN_STROKE_PX (at 256 px, scaled with `size`) are widened first
   at the source resolution, so a big scan of a fine pen does not fade to grey when shrunk.
5. Resize the square to `size` (area averaging down, bilinear up) and encode ink = 1 - paper-normalised value.

Kinds (`KINDS`): "sketch" (1 channel: black strokes on white; RGB input is converted to grey), "strokes"
(3 channels: colour strokes on white, the trunk input) and "photo" (3 channels: a photo's RGB as it is, the tree
mask network's input: none of the steps above, the whole image centred in a square, black outside, resized to
`size`). The crop is returned by `prepare` so that training
targets (depth maps of the same view) are cut by `apply_crop` exactly like their input.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from species.errors import TreefarmError

__all__ = ["ink_mask", "ground_line", "KINDS", "MARGIN", "MIN_STROKE_PX", "SPECK_SHARE", "Crop", "Prepared", "PreprocessError", "preprocess",
           "prepare", "apply_crop", "paper_image"]

KINDS = {"sketch": 1, "strokes": 3, "photo": 3}
MARGIN = 0.05             # of the drawing's larger side, on each side of its bounding box
# Thinnest stroke (pixels at a 256 px input) a drawing keeps after resizing: the renders' lines are 1-2 px
# (sketches) and 4 px (trunk strokes) at the networks' sizes.
MIN_STROKE_PX = {"sketch": 1.5, "strokes": 3.0}
SPECK_SHARE = 2e-5        # ink components below this share of the image's pixels are dust, not drawing
MIN_CONTRAST = 0.08       # ink must differ from the paper by this much (0..1) or the image is blank
_BORDER_SHARE = 0.02      # width of the border ring that gives the paper level, share of the smaller side
_INK_PERCENTILE = 10.0    # the ink level: this percentile of the clearly-inked pixels' values (dark cores)
_INK_CANDIDATE = 0.25     # share of the paper-to-darkest range a pixel must reach to count when finding ink level
# A ground line (sketch kind): a near-horizontal stroke at least GROUND_RUN of the drawing's larger side long, in
# the lowest GROUND_BAND of its height, reaching GROUND_OVERHANG of its width beyond the drawing just above it.
GROUND_RUN = 0.15
GROUND_BAND = 0.12
GROUND_OVERHANG = 0.08


class PreprocessError(TreefarmError):
    """An image the networks cannot read: wrong shape or dtype, an unknown kind or size, or a blank page."""


@dataclass(frozen=True)
class Crop:
    """The square window of a source image that becomes the network input: x in [x0, x0 + side) and y in
    [y0, y0 + side), source pixels, sub-pixel (pixel (i, j) spans x in [j, j + 1)); it may reach outside the
    image, where paper (or a map's background) is filled in.

    A network pixel (u, v) of an input of `size` px has its centre at source x = x0 + (u + 0.5) * side / size,
    less the source's half-pixel: `to_source` maps points back, for outputs that are images of the same view.
    """

    x0: float
    y0: float
    side: float

    def to_source(self, uv: np.ndarray, size: int) -> np.ndarray:
        """(N, 2) float64 source pixel coordinates (x, y) of network pixel coordinates uv (N, 2) (u, v)."""
        uv = np.asarray(uv, np.float64)
        return np.array([self.x0, self.y0], np.float64) + (uv + 0.5) * (self.side / size) - 0.5


@dataclass(frozen=True)
class Prepared:
    """A preprocessed input: `image` float32 (C, size, size) ink on 0 paper, and the `crop` it was cut with."""

    image: np.ndarray
    crop: Crop


def _check(image, kind: str, size: int) -> np.ndarray:
    if kind not in KINDS:
        raise PreprocessError(f"kind {kind!r} is unknown: allowed {', '.join(KINDS)}")
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not 8 <= size <= 4096:
        raise PreprocessError(f"size {size!r} is invalid: allowed an integer in [8, 4096]")
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (3, 4)) or min(image.shape[:2]) < 4:
        raise PreprocessError(f"image of shape {image.shape} is invalid: allowed (H, W) grey, (H, W, 3) RGB or "
                              f"(H, W, 4) RGBA, at least 4 x 4 pixels")
    if image.dtype == np.uint8:
        return image.astype(np.float32) / 255.0
    if image.dtype == np.uint16:
        return image.astype(np.float32) / 65535.0
    if np.issubdtype(image.dtype, np.floating):
        values = image.astype(np.float32)
        if not np.all(np.isfinite(values)) or values.min() < -1e-3 or values.max() > 1 + 1e-3:
            raise PreprocessError(f"float image has values outside [0, 1] (or NaN): allowed [0, 1], or uint8 / "
                                  f"uint16 pixels")
        return np.clip(values, 0.0, 1.0)
    raise PreprocessError(f"image dtype {image.dtype} is invalid: allowed uint8, uint16 or float in [0, 1]")


def _over_white(image: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, 3) float32: an RGBA image composited over white paper; others as they are."""
    if image.ndim == 3 and image.shape[2] == 4:
        alpha = image[..., 3:]
        return image[..., :3] * alpha + (1.0 - alpha)
    return image


def _border(image: np.ndarray) -> np.ndarray:
    """(P, ...) the pixels of the border ring."""
    h, w = image.shape[:2]
    t = max(1, int(round(_BORDER_SHARE * min(h, w))))
    ring = np.ones((h, w), bool)
    ring[t:h - t, t:w - t] = False
    return image[ring]


def _stretch(ink: np.ndarray) -> np.ndarray:
    """Ink strength (H, W) float32 (0 = paper) rescaled so the typical dark stroke is 1 (clipped)."""
    darkest = float(ink.max())
    if darkest < MIN_CONTRAST:
        raise PreprocessError(f"the image is blank: its darkest mark differs from the paper by {darkest:.3f} "
                              f"(allowed at least {MIN_CONTRAST}); draw on the image or check the file")
    candidates = ink[ink >= _INK_CANDIDATE * darkest]
    level = max(float(np.percentile(candidates, 100.0 - _INK_PERCENTILE)), MIN_CONTRAST)
    return np.clip(ink / level, 0.0, 1.0)


def paper_image(image, kind: str) -> np.ndarray:
    """The image as ink strength on paper: float32 (H, W, C) in [0, 1], 0 = paper, 1 = full ink (sketch: C = 1,
    the darkness; strokes: C = 3, 1 - RGB of the stroke colour over white). Steps 1 of the module docstring."""
    values = _over_white(_check(image, kind, 256))
    if kind == "sketch":
        grey = cv2.cvtColor(values, cv2.COLOR_RGB2GRAY) if values.ndim == 3 else values
        paper = float(np.median(_border(grey)))
        ink = (grey - paper) if paper < 0.5 else (paper - grey)  # dark paper: light strokes are the ink
        return _stretch(np.clip(ink, 0.0, None).astype(np.float32))[..., None]
    rgb = values if values.ndim == 3 else np.repeat(values[..., None], 3, axis=2)
    paper = np.median(_border(rgb), axis=0).astype(np.float32)
    # Colour strokes are solid: a pixel half way from the paper to the typical stroke is all stroke (a dark
    # colour on a black canvas is as much a stroke as a bright one).
    strength = np.clip(2.0 * _stretch(np.abs(rgb - paper).max(axis=2)), 0.0, 1.0)
    if paper.mean() >= 0.5:
        # Light paper: white-balance to it, so a scan's cream paper and dulled colours come out as drawn.
        colour = np.clip(rgb / np.maximum(paper, 1e-3), 0.0, 1.0)
    else:
        colour = rgb  # a dark canvas: keep the stroke colours, replace the paper by white below
    # Blend toward white by the stroke strength: paper -> white exactly, strokes keep their colour.
    over_white = strength[..., None] * colour + (1.0 - strength[..., None])
    return (1.0 - over_white).astype(np.float32)


def _ink_mask(ink: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels at least half inked, specks (dust) removed."""
    mask = (ink.max(axis=2) >= 0.5).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= max(2.0, SPECK_SHARE * mask.size)
    big[0] = False
    kept = big[labels]
    if not kept.any():
        kept = mask > 0  # only specks: a tiny drawing is still a drawing
    if not kept.any():
        raise PreprocessError("the image is blank: no stroke is darker than half way from paper to ink")
    return kept


def ground_line(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the ink of a ground line under a drawn tree (empty when there is none): a near-horizontal
    stroke at the foot of the drawing (GROUND_RUN, GROUND_BAND) that reaches beyond the drawing just above it
    (GROUND_OVERHANG), with whatever else lies beside the tree at that height (grass, an arrow's head). A tree's
    own foot (a trunk closed by a short line, roots, a bush's flat base) does not reach out that far. People draw
    the ground; the renders the networks learnt from have none."""
    mask = np.asarray(mask, bool)
    ground = np.zeros_like(mask)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return ground
    top, bottom, height, width = rows[0], rows[-1], rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1
    run = max(5, int(round(GROUND_RUN * max(height, width))))
    # Smeared up and down by a stroke's width so a wavy or slightly slanted line is one horizontal run.
    smear = int(np.ceil(_stroke_width(mask))) + 1
    ink = mask.astype(np.uint8)
    smeared = cv2.dilate(ink, np.ones((2 * smear + 1, 1), np.uint8))
    runs = cv2.morphologyEx(smeared, cv2.MORPH_OPEN, np.ones((1, run), np.uint8)) & ink
    count, labels, stats, _ = cv2.connectedComponentsWithStats(runs, connectivity=8)
    band_top = bottom - GROUND_BAND * height - 2 * smear
    lines = [i for i in range(1, count) if stats[i, cv2.CC_STAT_TOP] >= band_top]
    if not lines:
        return ground
    line_top = int(min(stats[i, cv2.CC_STAT_TOP] for i in lines)) - smear
    # What is drawn just above the line (the trunk's foot for a tree standing on it).
    band = slice(max(top, int(line_top - 2 * GROUND_BAND * height)), max(top, line_top))
    above = mask[band] & (labels[band] == 0)
    above_cols = np.flatnonzero(above.any(axis=0))
    if above_cols.size == 0:
        return ground  # nothing drawn above the line: the drawing is the line
    # The ground passes under the tree; roots spread from it in runs that stop short of its middle.
    middle = int(np.median(np.nonzero(above)[1]))
    left, span = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_WIDTH]
    lines = [i for i in lines if left[i] <= middle < left[i] + span[i]]
    if not lines:
        return ground
    line = np.isin(labels, lines)
    line_cols = np.flatnonzero(line.any(axis=0))
    overhang = max(above_cols[0] - line_cols[0], line_cols[-1] - above_cols[-1])
    if overhang < GROUND_OVERHANG * width:
        return ground
    # Beside the tree everything at the line's height goes; under it only the line's own flat ink, so the trunk
    # keeps its strokes down to the ground.
    flat = cv2.morphologyEx(ink, cv2.MORPH_OPEN, np.ones((1, 2 * smear + 1), np.uint8)) > 0
    ground[line_top:] = mask[line_top:]
    under = slice(above_cols[0], above_cols[-1] + 1)
    ground[line_top:, under] = line[line_top:, under] & flat[line_top:, under]
    return ground


def _drawing_ink(ink: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) bool each: the drawing's ink pixels (`_ink_mask`) less a sketch's ground line, and that line (empty
    for the other kinds, whose strokes are drawn on the tree only)."""
    mask = _ink_mask(ink)
    ground = ground_line(mask) if kind == "sketch" else np.zeros_like(mask)
    return mask & ~ground, ground


def ink_mask(image, kind: str = "sketch") -> np.ndarray:
    """(H, W) bool: where `image` is inked, as `prepare` finds it (paper level from the border, ink level
    stretched, dust removed, a sketch's ground line left out: `ground_line`), at the image's own size;
    PreprocessError for a blank image."""
    return _drawing_ink(paper_image(image, kind), kind)[0]


def _crop_of(mask: np.ndarray) -> Crop:
    """The square around the mask's bounding box (pixel edges, so a drawing's size is the same at any scale)."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    y_lo, y_hi, x_lo, x_hi = rows[0], rows[-1] + 1.0, cols[0], cols[-1] + 1.0
    side = max(y_hi - y_lo, x_hi - x_lo) * (1.0 + 2.0 * MARGIN)
    return Crop(float((x_lo + x_hi - side) / 2.0), float((y_lo + y_hi - side) / 2.0), float(side))


def _stroke_width(mask: np.ndarray) -> float:
    """Typical stroke width (pixels) of an ink mask (H, W) bool, from the mean distance to paper inside it
    (a stripe w px wide has mean distance about w / 4 + 1/2 under OpenCV's L2 distance transform)."""
    distance = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 3)
    return max(1.0, 4.0 * (float(distance[mask].mean()) - 0.5))


def _widen(ink: np.ndarray, pixels: int) -> np.ndarray:
    """Ink (H, W, C) grown by `pixels` on every side: each new pixel takes the ink of its strongest neighbour
    within the disc (a grey max filter per channel keeps colours, as trunk strokes rarely touch)."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * pixels + 1, 2 * pixels + 1))
    grown = cv2.dilate(ink, kernel)
    return grown.reshape(ink.shape)


def apply_crop(image: np.ndarray, crop: Crop, size: int, fill, interpolation: int = cv2.INTER_NEAREST) -> np.ndarray:
    """The crop's square of `image` (H, W) or (H, W, C) (C <= 4), `fill` outside the image, resampled to
    (size, size[, C]) with sub-pixel accuracy.

    fill : a number or a value per channel (the map's background). interpolation : cv2.INTER_NEAREST for maps
    whose values must stay exact (depth, masks), cv2.INTER_LINEAR for pictures (shrunk by area averaging first,
    so thin lines are averaged, not skipped).
    """
    image = np.asarray(image)
    h, w = image.shape[:2]
    sx = sy = 1.0
    scale = size / crop.side
    if interpolation != cv2.INTER_NEAREST and scale < 1.0:
        small = (max(1, int(round(w * scale))), max(1, int(round(h * scale))))
        sx, sy = small[0] / w, small[1] / h
        image = cv2.resize(image, small, interpolation=cv2.INTER_AREA).reshape(small[::-1] + image.shape[2:])
    # Network pixel centre u + 0.5 sits at source edge coordinate x0 + (u + 0.5) side / size; the (pre-shrunk)
    # source pixel j's centre at edge coordinate (j + 0.5) / sx.
    a, c = scale / sx, scale / sy
    matrix = np.array([[a, 0.0, (0.5 / sx - crop.x0) * scale - 0.5], [0.0, c, (0.5 / sy - crop.y0) * scale - 0.5]])
    channels = image.shape[2] if image.ndim == 3 else 1
    values = np.broadcast_to(np.asarray(fill, np.float64), (channels,))
    border = tuple(float(v) for v in values) + (0.0,) * (4 - channels)
    out = cv2.warpAffine(image, matrix, (size, size), flags=interpolation, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=border)
    return out.reshape((size, size) + image.shape[2:])


def prepare(image, kind: str, size: int) -> Prepared:
    """`preprocess` with the crop it used (for cutting a training target of the same view alike)."""
    if kind == "photo":
        return _prepare_photo(image, size)
    _check(image, kind, size)
    ink = paper_image(image, kind)
    mask, ground = _drawing_ink(ink, kind)
    if ground.any():
        # The line's faint anti-aliased edge goes with it.
        ink[(cv2.dilate(ground.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0) & ~mask] = 0.0
    crop = _crop_of(mask)
    scale = size / crop.side
    wanted = MIN_STROKE_PX[kind] * size / 256.0 / scale  # source pixels
    missing = int(np.ceil((wanted - _stroke_width(mask)) / 2.0))
    if missing > 0:
        ink = _widen(ink, missing)
    network = apply_crop(ink, crop, size, 0.0, cv2.INTER_LINEAR)
    if network.ndim == 2:
        network = network[..., None]
    return Prepared(np.ascontiguousarray(np.moveaxis(network, 2, 0), np.float32), crop)


def _prepare_photo(image, size: int) -> Prepared:
    """A photo as the network input (kind "photo"): RGB in [0, 1], the whole image centred in a square."""
    values = _check(image, "photo", size)
    rgb = values[..., :3] if values.ndim == 3 else np.repeat(values[..., None], 3, axis=2)
    h, w = rgb.shape[:2]
    side = float(max(h, w))
    crop = Crop((w - side) / 2.0, (h - side) / 2.0, side)
    network = apply_crop(np.ascontiguousarray(rgb, np.float32), crop, size, 0.0, cv2.INTER_LINEAR)
    return Prepared(np.ascontiguousarray(np.moveaxis(network, 2, 0), np.float32), crop)


def preprocess(image, kind: str, size: int) -> np.ndarray:
    """A drawing as the network input: float32 (C, size, size), ink in [0, 1] on paper 0 (C = KINDS[kind]).

    image : (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA; uint8, uint16 or float in [0, 1]; dark strokes on light
            paper or light strokes on dark. kind : "sketch" or "strokes". size : the network's input size, pixels.
    Raises PreprocessError for a blank image, a bad shape or dtype, an unknown kind.
    """
    return prepare(image, kind, size).image
