"""Distances to a convex polygon's boundary (:class:`tritools.model.regions.Polytope`'s ``closest_point``): the
vectorised search over blocks of points x edges at unit scale around the polygon, and its scalar twin for one point
(bit for bit, tests/test_regions_polytope_twin.py); the affine map ``B p + c`` of the containment test."""
from __future__ import annotations

import numpy as np

__all__ = ["closest_on_boundary", "closest_on_boundary_one", "unit_edges", "affine"]


def closest_on_boundary(Q: np.ndarray, V: np.ndarray, chunk: int) -> np.ndarray:
    """Closest points of the closed polygonal boundary through V (k, 2) (a segment for k = 2,
    a point for k = 1) to the rows of Q, over blocks of points x edges."""
    if len(V) == 1:
        return np.broadcast_to(V[0], Q.shape).copy()
    # at unit scale around the polygon, so that squared lengths neither overflow nor underflow; a point
    # farther than 1e150 polygon sizes is moved along its direction to that distance (same closest point
    # to within 1e-150 relative)
    mean = (V / 2.0).mean(axis=0) * 2.0
    span = float(np.max(np.abs(V - mean)))
    with np.errstate(over="ignore", invalid="ignore"):
        Qs = (Q - mean) / span
    far = ~(np.max(np.abs(Qs), axis=1) <= 1e150)
    if np.any(far):
        d = Q[far] / 2.0 - mean / 2.0
        Qs[far] = 1e150 * (d / np.max(np.abs(d), axis=1, keepdims=True))
    return mean + span * _closest_unit(Qs, (V - mean) / span, chunk)


def affine(P: np.ndarray, B: np.ndarray, c: np.ndarray) -> np.ndarray:
    """B p + c for the rows p of P (m, 2) -> (m, k), elementwise (p_1 B_k1 + p_2 B_k2 + c_k, no BLAS): the same
    bits for a point whatever the batch it is in (a matrix product's kernel, and its rounding, depend on the
    shapes)."""
    return P[:, :1] * B[:, 0] + P[:, 1:] * B[:, 1] + c


def unit_edges(V: np.ndarray) -> tuple:
    """(mean (2,), span, [(a, e), ...]): the vertices' mean and largest deviation as :func:`closest_on_boundary`
    computes them, and the edges (a -> e, Python floats) of the boundary at unit scale in :func:`_closest_unit`'s
    order (the closed cycle for k > 2 vertices, the segment for k = 2, none for one vertex)."""
    if len(V) == 1:
        return V[0].copy(), 1.0, []                 # the point itself
    mean = (V / 2.0).mean(axis=0) * 2.0
    span = float(np.max(np.abs(V - mean)))
    U = ((V - mean) / span).tolist()
    edges = [(U[k], U[(k + 1) % len(U)]) for k in range(len(U))] if len(U) > 2 else [(U[0], U[1])]
    return mean, span, edges


def closest_on_boundary_one(q: np.ndarray, unit: tuple) -> tuple:
    """The scalar twin of :func:`closest_on_boundary` for one point ``q`` (2,) and the boundary ``unit`` of
    :func:`unit_edges`: the same operations in Python floats over the edges in order, the first nearest edge kept
    (numpy's argmin), bit for bit (tests/test_regions_polytope_twin.py); a single call's distance without ~40 small
    numpy operations."""
    mean, span, edges = unit
    if not edges:
        return float(mean[0]), float(mean[1])
    with np.errstate(over="ignore", invalid="ignore"):
        qs = (q - mean) / span
    qx, qy = float(qs[0]), float(qs[1])
    if not max(abs(qx), abs(qy)) <= 1e150:
        d = q / 2.0 - mean / 2.0
        d = 1e150 * (d / np.max(np.abs(d)))
        qx, qy = float(d[0]), float(d[1])
    bd, bx, by = float("inf"), 0.0, 0.0
    for (ax, ay), (ex, ey) in edges:
        dx, dy = ex - ax, ey - ay
        dd = dx * dx + dy * dy
        if not dd > 0:
            dd = 1.0
        t = min(max(((qx - ax) * dx + (qy - ay) * dy) / dd, 0.0), 1.0)
        cx, cy = ax + t * dx, ay + t * dy
        dist = (qx - cx) * (qx - cx) + (qy - cy) * (qy - cy)        # numpy's square: x * x
        if dist < bd:
            bd, bx, by = dist, cx, cy
    return float(mean[0]) + span * bx, float(mean[1]) + span * by


def _closest_unit(Q: np.ndarray, V: np.ndarray, chunk: int) -> np.ndarray:
    """:func:`closest_on_boundary` for a polygon of size ~1 (at least 2 vertices)."""
    A = V if len(V) > 2 else V[:1]
    D = (np.roll(V, -1, axis=0) if len(V) > 2 else V[1:]) - A
    dd = np.sum(D * D, axis=1)
    dd = np.where(dd > 0, dd, 1.0)
    best = np.empty_like(Q)
    qstep = max(1, min(len(Q), chunk // 64))
    estep = max(1, chunk // qstep)
    for qs in range(0, len(Q), qstep):
        q = Q[qs:qs + qstep]
        bd = np.full(len(q), np.inf)
        bp = np.empty_like(q)
        for es in range(0, len(A), estep):
            a, d = A[es:es + estep], D[es:es + estep]
            rx = q[:, None, 0] - a[None, :, 0]
            ry = q[:, None, 1] - a[None, :, 1]
            t = np.clip((rx * d[None, :, 0] + ry * d[None, :, 1]) / dd[None, es:es + estep], 0.0, 1.0)
            cx = a[None, :, 0] + t * d[None, :, 0]
            cy = a[None, :, 1] + t * d[None, :, 1]
            dist = (q[:, None, 0] - cx) ** 2 + (q[:, None, 1] - cy) ** 2
            j = np.argmin(dist, axis=1)
            rows = np.arange(len(q))
            better = dist[rows, j] < bd
            bd[better] = dist[rows, j][better]
            bp[better, 0] = cx[rows, j][better]
            bp[better, 1] = cy[rows, j][better]
        best[qs:qs + qstep] = bp
    return best
