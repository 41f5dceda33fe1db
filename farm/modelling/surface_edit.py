"""Edits of drawn shapes (seed 000 ch. 5): a stroke's span dragged as a quadratic Bezier (eq. 5.2) and a lobe's
surface dragged by Laplacian editing (eq. 5.3-5.5).

In: a stroke (K, 3) or a mesh's vertices (V, 3) float metres and faces (F, 3) int, the grabbed point and its
target (3,) metres. Out: the new points, same shapes; a mesh keeps its faces, so a closed lobe stays closed.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
from scipy.sparse.csgraph import dijkstra
from scipy.sparse.linalg import splu

from species.errors import TreefarmError
from species.geometry.vectors import row_norms

from .strokes import stroke_is_closed

__all__ = ["EditError", "bezier_drag", "laplacian_edit", "umbrella_laplacian", "edit_region"]


class EditError(TreefarmError):
    """An edit that cannot be made: an index out of range, a non-finite target, an empty region."""


def _target(target) -> np.ndarray:
    target = np.asarray(target, np.float64).reshape(-1)
    if target.shape != (3,) or not np.all(np.isfinite(target)):
        raise EditError(f"the drag target is {target.tolist()}; allowed: three finite coordinates (metres)")
    return target


def bezier_drag(stroke, index: int, target, span: int | None = None) -> np.ndarray:
    """(K, 3) float64: `stroke` with the samples within `span` of `index` replaced by a quadratic Bezier (eq. 5.2)
    from P1 = stroke[index - span] to P2 = stroke[index + span] that passes through `target` where sample `index`
    was (its control point P_c solved for that). span defaults to a quarter of the stroke's samples; on an open
    stroke the span is cut at the ends, and dragging an end moves it with P_c at the span's old middle. A closed
    stroke wraps round.
    """
    stroke = np.asarray(stroke, np.float64)
    if stroke.ndim != 2 or stroke.shape[1] != 3 or len(stroke) < 3:
        raise EditError(f"a stroke to drag must have shape (K >= 3, 3); got {stroke.shape}")
    k = len(stroke)
    if not 0 <= index < k:
        raise EditError(f"drag index {index} is outside the stroke; allowed: 0..{k - 1}")
    target = _target(target)
    span = max(1, k // 4) if span is None else int(span)
    if span < 1:
        raise EditError(f"drag span is {span}; allowed: at least 1 sample")
    closed = stroke_is_closed(stroke)
    if closed:
        span = min(span, (k - 1) // 2)
        first, last = index - span, index + span
    else:
        first, last = max(0, index - span), min(k - 1, index + span)
    out = stroke.copy()
    ids = np.arange(first, last + 1) % k
    t = np.linspace(0.0, 1.0, len(ids))
    t0 = (index - first) / (last - first)
    p1, p2 = stroke[first % k], stroke[last % k]
    if 0.0 < t0 < 1.0:
        control = (target - (1 - t0) ** 2 * p1 - t0 ** 2 * p2) / (2 * t0 * (1 - t0))
    else:
        control = stroke[ids[len(ids) // 2]]
        p1, p2 = (target, p2) if t0 == 0.0 else (p1, target)
    out[ids] = ((1 - t) ** 2)[:, None] * p1 + (2 * t * (1 - t))[:, None] * control + (t ** 2)[:, None] * p2
    return out


def umbrella_laplacian(faces: np.ndarray, count: int) -> sparse.csr_matrix:
    """(V, V) sparse L = I - D^-1 A of a mesh's edge graph (eq. 5.4): A the 0/1 adjacency, D the degrees."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    rows, cols = np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]])
    adjacency = sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(count, count))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return (sparse.identity(count, format="csr") - sparse.diags(1.0 / np.maximum(degree, 1)) @ adjacency).tocsr()


def edit_region(vertices: np.ndarray, faces: np.ndarray, handle: int, radius: float) -> np.ndarray:
    """(V,) bool: the vertices within `radius` metres of the handle along the mesh's edges (a geodesic estimate
    that does not jump across a thin lobe)."""
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1),
                      axis=0)
    length = row_norms(vertices[edges[:, 0]] - vertices[edges[:, 1]])
    graph = sparse.csr_matrix((length, (edges[:, 0], edges[:, 1])), shape=(len(vertices),) * 2)
    distance = dijkstra(graph, directed=False, indices=handle, limit=radius)
    return np.isfinite(distance)


def laplacian_edit(vertices, faces, handle: int, target, radius: float) -> np.ndarray:
    """(V, 3) float64: the mesh's vertices after dragging vertex `handle` to `target` (eq. 5.3-5.5).

    The vertices within `radius` metres of the handle (along the mesh's edges: `edit_region`) move so that their
    Laplacian coordinates delta = L V (umbrella weights, eq. 5.3-5.4) change least in the least-squares sense; the
    handle is held at the target and every vertex beyond the radius stays exactly where it was (both as hard
    constraints, eq. 5.5's large weight taken to its limit). Solved by sparse normal equations.
    """
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 or not len(faces):
        raise EditError(f"a mesh to edit needs vertices (V, 3) and faces (F > 0, 3); got {vertices.shape} and "
                        f"{faces.shape}")
    if not 0 <= handle < len(vertices):
        raise EditError(f"handle vertex {handle} is outside the mesh; allowed: 0..{len(vertices) - 1}")
    if not (np.isfinite(radius) and radius > 0):
        raise EditError(f"edit radius is {radius!r}; allowed: a finite length > 0 metres")
    target = _target(target)
    laplacian = umbrella_laplacian(faces, len(vertices))
    delta = laplacian @ vertices
    free = edit_region(vertices, faces, handle, radius)
    free[handle] = False
    out = vertices.copy()
    out[handle] = target
    if not free.any():
        return out
    fixed = ~free
    # min || L_free X + L_fixed V_fixed - delta ||^2 over the free vertices X.
    l_free, l_fixed = laplacian[:, free], laplacian[:, fixed]
    rhs = delta - l_fixed @ out[fixed]
    normal = (l_free.T @ l_free).tocsc()
    out[free] = splu(normal).solve(np.asarray(l_free.T @ rhs))
    return out
