"""Douglas-Peucker keys of many polylines at once: for every point, the largest tolerance at which the algorithm
would still keep it, so one pass answers every tolerance (keep the points whose key exceeds it).

In: concatenated points (K, 3) metres, radii (K,) metres and polyline offsets (P + 1,). Out: keys (K,) metres.
"""
from __future__ import annotations

import numpy as np

__all__ = ["simplification_keys"]


def simplification_keys(points: np.ndarray, radius: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(K,) float64 metres: Douglas-Peucker key of every point of the polylines points[offsets[i]:offsets[i+1]].

    points : (K, 3) float metres; radius : (K,) float metres (tube radius, so a bulge of the tube counts as
    error too); offsets : (P + 1,) int, ascending, offsets[0] = 0, offsets[-1] = K.
    A point's error against a chord is its distance to the chord plus how far its radius is from the radius
    interpolated along the chord. Simplifying with tolerance e keeps the points whose key is > e: the polyline
    ends (key inf) and every point Douglas-Peucker splits at before its segment falls within e. Keys never
    exceed the key of the split that made their segment, so the kept sets are nested as e grows. Level by
    level over all segments of all polylines at once (a Python loop over recursion depth only).
    """
    points = np.asarray(points, np.float64)
    radius = np.asarray(radius, np.float64)
    offsets = np.asarray(offsets, np.int64)
    keys = np.zeros(len(points))
    ends = offsets[1:] > offsets[:-1]
    keys[offsets[:-1][ends]] = np.inf
    keys[offsets[1:][ends] - 1] = np.inf
    lo, hi = offsets[:-1][ends], offsets[1:][ends] - 1
    cap = np.full(len(lo), np.inf)
    while True:
        open_ = hi - lo >= 2
        lo, hi, cap = lo[open_], hi[open_], cap[open_]
        if len(lo) == 0:
            return keys
        count = hi - lo - 1  # interior points per segment, contiguous after `lo`
        first = np.cumsum(count) - count
        segment = np.repeat(np.arange(len(lo)), count)
        inner = lo[segment] + 1 + (np.arange(int(count.sum())) - first[segment])
        a, b = points[lo][segment], points[hi][segment]
        chord = b - a
        length2 = np.einsum("ij,ij->i", chord, chord)
        t = np.clip(np.einsum("ij,ij->i", points[inner] - a, chord) / np.maximum(length2, 1e-300), 0.0, 1.0)
        off_axis = np.linalg.norm(points[inner] - (a + t[:, None] * chord), axis=1)
        bulge = np.abs(radius[inner] - (radius[lo][segment] + t * (radius[hi][segment] - radius[lo][segment])))
        error = off_axis + bulge
        worst = np.maximum.reduceat(error, first)
        # The first point reaching its segment's maximum (lowest index on ties), as the recursive form splits.
        at_max = np.flatnonzero(error == worst[segment])
        at_max = at_max[np.r_[True, segment[at_max][1:] != segment[at_max][:-1]]]
        split = inner[at_max]
        key = np.minimum(worst, cap)
        keys[split] = key
        go = worst > 0.0  # a straight, even segment needs none of its points at any tolerance
        lo, hi, cap = (np.concatenate([lo[go], split[go]]), np.concatenate([split[go], hi[go]]),
                       np.concatenate([key[go], key[go]]))
