"""Shadow propagation (digest 1.3): light as the resource, on a voxel grid of shadow values.

Each node shades a pyramid of voxels below it (a * b^-q on the full square layer q down); a bud's exposure is
Q = max(C - s + a, 0); its optimal direction points to the least shaded neighbour voxel in its cone and the space.
"""
from __future__ import annotations

import numpy as np

from .growth_space import GrowthSpace

__all__ = ["ShadowGrid"]


class ShadowGrid:
    """Shadow values s on a grid of cubic voxels covering a growth space (metres, Z up).

    space   : the growth space; voxels whose centre lies outside it are dark.
    voxel   : voxel edge, metres (digest: 1 internode length).
    a, b    : shadow of a node in its own voxel, and the fall-off base per layer (b > 1).
    depth   : q_max, layers the pyramid reaches below a node.
    exposure: C, the light a bud gets in an unshaded voxel.
    include : (P, 3) metres, points outside the space the grid must also cover (the seed nodes).
    """

    def __init__(self, space: GrowthSpace, voxel: float, a: float = 1.0, b: float = 2.0, depth: int = 6,
                 exposure: float = 1.0, include: np.ndarray | None = None):
        self.voxel, self.a, self.exposure = float(voxel), float(a), float(exposure)
        lo, hi = space.bounds
        if include is not None and len(include):  # e.g. the bole below the crown
            lo, hi = np.minimum(lo, include.min(axis=0)), np.maximum(hi, include.max(axis=0))
        pad = (depth + 1) * self.voxel
        # Voxel centres on whole multiples of the voxel from the origin, so a straight bole of
        # one-voxel internodes puts one node per voxel instead of two in a boundary voxel.
        self.origin = (np.floor((lo - pad) / self.voxel) - 0.5) * self.voxel
        self.shape = tuple(np.ceil((hi + pad - self.origin) / self.voxel).astype(int) + 1)
        ijk = np.indices(self.shape).reshape(3, -1).T
        centres = self.origin + (ijk + 0.5) * self.voxel
        self.shadow = np.zeros(len(centres))
        # Buds never turn toward voxels whose centre is outside the space; growth itself is clipped by the
        # space, so a bud in a boundary voxel still gets its light.
        self.inside = space.contains(centres)
        layers = [(di, dj, -q, a * b ** (-q)) for q in range(depth + 1)
                  for di in range(-q, q + 1) for dj in range(-q, q + 1)]
        kernel = np.array(layers)
        self._kernel_offsets = kernel[:, :3].astype(np.int64)
        self._kernel_values = kernel[:, 3]
        self._strides = np.array([self.shape[1] * self.shape[2], self.shape[2], 1], np.int64)
        nb = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)])
        self._neighbours = nb
        self._neighbour_dirs = nb / np.linalg.norm(nb, axis=1, keepdims=True)

    def _cells(self, positions: np.ndarray) -> np.ndarray:
        ijk = np.floor((np.asarray(positions, np.float64) - self.origin) / self.voxel).astype(np.int64)
        return np.clip(ijk, 0, np.array(self.shape) - 1)

    def cast(self, positions: np.ndarray, sign: float = 1.0) -> None:
        """Add (sign +1) or remove (-1) the shadow pyramids of nodes at positions (P, 3) metres."""
        if not len(positions):
            return
        cells = self._cells(positions)[:, None, :] + self._kernel_offsets[None]  # (P, K, 3)
        valid = np.all((cells >= 0) & (cells < np.array(self.shape)), axis=2)
        flat = (cells @ self._strides)[valid]
        values = np.broadcast_to(self._kernel_values, valid.shape)[valid]
        self.shadow += sign * np.bincount(flat, weights=values, minlength=self.shadow.size)

    def light(self, positions: np.ndarray) -> np.ndarray:
        """(P,) float64 in [0, 1]: eq. 2.2, Q = max(C - s + a, 0) / C; the +a cancels the bud's own shadow.

        Dividing by C puts a fully lit bud at Q = 1, the scale space colonization gives a bud with markers,
        so alpha and lambda mean the same under both resources.
        """
        flat = self._cells(positions) @ self._strides
        return np.maximum(self.exposure - self.shadow[flat] + self.a, 0.0) / self.exposure

    def best_directions(self, positions: np.ndarray, directions: np.ndarray, cos_half_angle: float,
                        rule: str = "least_shaded") -> np.ndarray:
        """(P, 3) unit optimal directions, 0 where none: rule "least_shaded" points to the least shaded of the
        26 neighbour voxels in each bud's cone; "gradient" takes -grad(s) where it lies in the cone and is
        not flat, and the least shaded neighbour elsewhere."""
        least = self._least_shaded(positions, directions, cos_half_angle)
        if rule == "least_shaded":
            return least
        cells = np.clip(self._cells(positions)[:, None, :] + np.vstack([np.eye(3, dtype=np.int64),
                                                                          -np.eye(3, dtype=np.int64)])[None],
                        0, np.array(self.shape) - 1)
        shade = self.shadow[cells @ self._strides]  # (P, 6): +x +y +z -x -y -z
        downhill = (shade[:, 3:] - shade[:, :3]) / 2
        norm = np.linalg.norm(downhill, axis=1)
        unit = downhill / np.maximum(norm, 1e-12)[:, None]
        usable = (norm > 1e-6) & (np.einsum("pd,pd->p", unit, directions) >= cos_half_angle)
        return np.where(usable[:, None], unit, least)

    def _least_shaded(self, positions: np.ndarray, directions: np.ndarray, cos_half_angle: float) -> np.ndarray:
        cells = self._cells(positions)[:, None, :] + self._neighbours[None]
        cells = np.clip(cells, 0, np.array(self.shape) - 1)
        flat = cells @ self._strides
        shade = self.shadow[flat]  # (P, 26)
        in_cone = directions @ self._neighbour_dirs.T >= cos_half_angle
        shade = np.where(in_cone & self.inside[flat], shade, np.inf)
        best = np.argmin(shade, axis=1)
        found = np.isfinite(shade[np.arange(len(best)), best])
        return np.where(found[:, None], self._neighbour_dirs[best], 0.0)
