"""Training curves as a PNG: one panel per metric, its value per epoch, a dashed line where a baseline is given.

In: rows of per-epoch metrics (dicts with `epoch` and numbers, as `metrics.csv` holds them). Out: PNG bytes, drawn
with Pillow (no plotting library), the same rows giving the same bytes.
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
from PIL import Image, ImageDraw

__all__ = ["write_metrics_csv", "read_metrics_csv", "curves_png"]

_PANEL = (360, 220)   # width, height of one metric's panel, pixels
_MARGIN = (54, 28, 14, 30)  # left, top, right, bottom inside a panel
_SERIES_COLOURS = ((31, 119, 180), (214, 39, 40), (44, 160, 44), (148, 103, 189), (255, 127, 14))
_BASELINE_COLOUR = (120, 120, 120)


def write_metrics_csv(path: str | Path, rows: Sequence[Mapping[str, float]]) -> None:
    """Write per-epoch rows (the union of their keys as columns, `epoch` first; a missing value is empty)."""
    columns = ["epoch"] + sorted({key for row in rows for key in row} - {"epoch"})
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, restval="")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: _cell(value) for key, value in row.items()})


def _cell(value) -> str:
    return repr(float(value)) if isinstance(value, (float, np.floating)) else str(value)


def read_metrics_csv(path: str | Path) -> list[dict[str, float]]:
    """The rows `write_metrics_csv` wrote, numbers as floats (`epoch` as int), empty cells left out."""
    with open(path, newline="") as handle:
        rows = []
        for raw in csv.DictReader(handle):
            row = {key: float(value) for key, value in raw.items() if value not in ("", None)}
            row["epoch"] = int(row["epoch"])
            rows.append(row)
    return rows


def curves_png(rows: Sequence[Mapping[str, float]], panels: Sequence[tuple[str, Sequence[str]]],
               baselines: Mapping[str, float] | None = None, title: str = "") -> bytes:
    """PNG bytes: per panel (title, metric names) the metrics' values against epoch, a legend, and for each metric
    with a `baselines` entry a dashed grey line at that value. Panels lie two per row."""
    baselines = dict(baselines or {})
    columns = 2 if len(panels) > 1 else 1
    grid_rows = math.ceil(len(panels) / columns)
    header = 24 if title else 0
    image = Image.new("RGB", (columns * _PANEL[0], header + grid_rows * _PANEL[1]), "white")
    draw = ImageDraw.Draw(image)
    if title:
        draw.text((8, 6), title, fill="black")
    epochs = np.array([row["epoch"] for row in rows], float)
    for i, (panel_title, names) in enumerate(panels):
        left = (i % columns) * _PANEL[0]
        top = header + (i // columns) * _PANEL[1]
        _panel(draw, (left, top), panel_title, epochs,
               {name: np.array([row.get(name, np.nan) for row in rows], float) for name in names},
               {name: baselines[name] for name in names if name in baselines})
    buffer = io.BytesIO()
    image.save(buffer, format="PNG", optimize=False)
    return buffer.getvalue()


def _panel(draw: ImageDraw.ImageDraw, origin: tuple[int, int], title: str, epochs: np.ndarray,
           series: dict[str, np.ndarray], baselines: dict[str, float]) -> None:
    left, top = origin
    x0, y0 = left + _MARGIN[0], top + _MARGIN[1]
    x1, y1 = left + _PANEL[0] - _MARGIN[2], top + _PANEL[1] - _MARGIN[3]
    draw.text((left + _MARGIN[0], top + 6), title, fill="black")
    draw.rectangle((x0, y0, x1, y1), outline=(180, 180, 180))
    values = np.concatenate([v[np.isfinite(v)] for v in series.values()] + [np.array(list(baselines.values()))])
    if len(epochs) == 0 or len(values) == 0:
        draw.text((x0 + 8, y0 + 8), "no values yet", fill=(120, 120, 120))
        return
    lo, hi = float(values.min()), float(values.max())
    if hi - lo < 1e-12:
        lo, hi = lo - 0.5 * max(abs(lo), 1.0), hi + 0.5 * max(abs(hi), 1.0)
    pad = 0.05 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    e_lo, e_hi = float(epochs.min()), float(epochs.max())
    e_span = max(e_hi - e_lo, 1.0)

    def to_xy(epoch: np.ndarray, value: np.ndarray) -> np.ndarray:
        x = x0 + (epoch - e_lo) / e_span * (x1 - x0)
        y = y1 - (value - lo) / (hi - lo) * (y1 - y0)
        return np.stack([x, y], axis=1)

    for tick in np.linspace(lo + pad, hi - pad, 4):
        y = y1 - (tick - lo) / (hi - lo) * (y1 - y0)
        draw.line((x0 - 3, y, x0, y), fill=(120, 120, 120))
        draw.text((left + 2, y - 6), f"{tick:.3g}", fill=(80, 80, 80))
    for tick in _epoch_ticks(e_lo, e_hi):
        x = x0 + (tick - e_lo) / e_span * (x1 - x0)
        draw.line((x, y1, x, y1 + 3), fill=(120, 120, 120))
        draw.text((x - 4, y1 + 5), str(int(tick)), fill=(80, 80, 80))
    draw.text((x1 - 34, y1 + 14), "epoch", fill=(80, 80, 80))
    for k, (name, value) in enumerate(series.items()):
        colour = _SERIES_COLOURS[k % len(_SERIES_COLOURS)]
        if name in baselines:
            _dashed(draw, x0, x1, y1 - (baselines[name] - lo) / (hi - lo) * (y1 - y0))
        finite = np.isfinite(value)
        points = to_xy(epochs[finite], value[finite])
        if len(points) > 1:
            draw.line([tuple(p) for p in points], fill=colour, width=2)
        for x, y in points:
            draw.ellipse((x - 2, y - 2, x + 2, y + 2), fill=colour)
        label = name + (" (- - baseline)" if name in baselines else "")
        draw.text((x0 + 6, y0 + 4 + 12 * k), label, fill=colour)


def _dashed(draw: ImageDraw.ImageDraw, x0: float, x1: float, y: float, dash: int = 6) -> None:
    for start in np.arange(x0, x1, 2 * dash):
        draw.line((start, y, min(start + dash, x1), y), fill=_BASELINE_COLOUR, width=1)


def _epoch_ticks(lo: float, hi: float) -> Iterable[float]:
    span = hi - lo
    step = max(1, int(math.ceil(span / 6)))
    return np.arange(math.ceil(lo), hi + 1e-9, step)
