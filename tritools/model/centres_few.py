"""Scalar twins of the camera-centre steps of :func:`tritools.model.stacked.fundamental_stack` for a few cameras.

A single call's stacks hold one or two problems of a few views; there numpy's cost per call (~1-3 us for every
operation on a 3x4 array) dominates the arithmetic.  These functions do the same operations, in the same order, on
Python floats, so they return the stacked functions' numbers bit for bit (``tests/test_centres_few.py``):

* :func:`null_vectors_few` -- :func:`tritools.model.stacked.null_vectors` (the signed 3x3 minors expanded along the
  first row, the operations of :func:`tritools.model.stacked._det3`; also the world frame's
  :func:`tritools.model.frame.world_origin_one`);
* :func:`centre_vectors_few` -- :func:`tritools.model.stacked.centre_vectors` (each camera divided by its largest
  |entry|, row 3 to unit norm, rows 1 and 2 made orthogonal to it twice, then the null vector);
* :func:`distinct_few` -- :func:`tritools.model.stacked.distinct_centres` (the sine of the angle between two
  homogeneous centres above ``SAME_CENTER_RTOL``).

Every sum here has at most four terms: numpy adds up to seven terms of a reduction one after the other from the
first, as Python's ``sum`` does, so the orders agree.  Only finite cameras are taken (:func:`few_centres` answers
None otherwise and the caller runs the stacked code): numpy's NaN propagation through ``maximum`` is not Python's
``max``.
"""
from __future__ import annotations

import math
import numpy as np

from .geometry import SAME_CENTER_RTOL

__all__ = ["null_vector_one", "null_vectors_few", "centre_vector_one", "centre_vectors_few", "distinct_few",
           "few_distinct", "FEW_CAMERAS"]

#: stacks of at most this many cameras (problems x views) take the scalar twins in
#: :func:`tritools.model.stacked.fundamental_stack`: a single call's one problem of up to 8 views, or its two
#: stacked problems of up to 4 (measured: ~40 % less time for 2-4 cameras, even at 8, slower from 10 on).
FEW_CAMERAS = 8


def _det3(a00, a01, a02, a10, a11, a12, a20, a21, a22) -> float:
    """det of a 3x3 matrix expanded along the first row: :func:`tritools.model.stacked._det3`'s operations."""
    return (a00 * (a11 * a22 - a12 * a21)
            - a01 * (a10 * a22 - a12 * a20)
            + a02 * (a10 * a21 - a11 * a20))


def null_vector_one(P: list) -> tuple:
    """The null vector (a_0, a_1, a_2, a_3) of one 3x4 matrix of floats (rows P[r]): a_k = (-1)^k det of the
    columns other than k, as :func:`tritools.model.stacked.null_vectors` (its sign applied by a product with
    -1.0, exact)."""
    (p00, p01, p02, p03), (p10, p11, p12, p13), (p20, p21, p22, p23) = P
    return (_det3(p01, p02, p03, p11, p12, p13, p21, p22, p23) * 1.0,
            _det3(p00, p02, p03, p10, p12, p13, p20, p22, p23) * -1.0,
            _det3(p00, p01, p03, p10, p11, p13, p20, p21, p23) * 1.0,
            _det3(p00, p01, p02, p10, p11, p12, p20, p21, p22) * -1.0)


def null_vectors_few(P: list) -> list:
    """:func:`null_vector_one` of each 3x4 matrix in a list."""
    return [null_vector_one(p) for p in P]


def centre_vector_one(P: list) -> tuple:
    """:func:`tritools.model.stacked.centre_vectors` of one finite camera (rows P[r]), unrolled: every sum of four
    terms added from the first, as numpy's reduction of four."""
    m = max(max(map(abs, P[0])), max(map(abs, P[1])), max(map(abs, P[2])))
    m = m if m > 0 else 1.0
    (a0, a1, a2, a3), (b0, b1, b2, b3), (c0, c1, c2, c3) = ((v / m for v in row) for row in P)
    n3 = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2 + c3 * c3)
    n3 = n3 if n3 > 0 else 1.0
    u0, u1, u2, u3 = c0 / n3, c1 / n3, c2 / n3, c3 / n3
    for _ in range(2):                      # rows 1 and 2 minus their component along row 3, twice
        d = a0 * u0 + a1 * u1 + a2 * u2 + a3 * u3
        a0, a1, a2, a3 = a0 - d * u0, a1 - d * u1, a2 - d * u2, a3 - d * u3
        d = b0 * u0 + b1 * u1 + b2 * u2 + b3 * u3
        b0, b1, b2, b3 = b0 - d * u0, b1 - d * u1, b2 - d * u2, b3 - d * u3
    return null_vector_one(((a0, a1, a2, a3), (b0, b1, b2, b3), (u0, u1, u2, u3)))


def centre_vectors_few(P: list) -> list:
    """:func:`centre_vector_one` of each finite camera in a list."""
    return [centre_vector_one(p) for p in P]


def distinct_few(a: tuple, b: tuple) -> bool:
    """:func:`tritools.model.stacked.distinct_centres` of two homogeneous centres (4-tuples of floats): the sine of
    their angle, ||u - (u . w) w|| for the unit vectors u, w, above ``SAME_CENTER_RTOL``; False where either is 0."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    na, nb = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3), math.sqrt(b0 * b0 + b1 * b1 + b2 * b2 + b3 * b3)
    if not (na > 0 and nb > 0):
        return False
    u0, u1, u2, u3 = a0 / na, a1 / na, a2 / na, a3 / na
    w0, w1, w2, w3 = b0 / nb, b1 / nb, b2 / nb, b3 / nb
    d = u0 * w0 + u1 * w1 + u2 * w2 + u3 * w3
    e0, e1, e2, e3 = u0 - d * w0, u1 - d * w1, u2 - d * w2, u3 - d * w3
    return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3) > SAME_CENTER_RTOL


def few_distinct(C: np.ndarray, I, J) -> np.ndarray | None:
    """distinct centres (M, K) for the pairs (I, J) of cameras C (M, N, 3, 4) by the scalar twins -- the numbers of
    :func:`tritools.model.stacked.fundamental_stack`'s stacked steps (:func:`~tritools.model.stacked.centre_vectors`,
    :func:`~tritools.model.stacked.distinct_centres`) -- or None for a stack of more than :data:`FEW_CAMERAS` cameras
    or with a non-finite entry."""
    M, N = C.shape[:2]
    if M * N > FEW_CAMERAS or not np.isfinite(C).all():
        return None
    pairs = list(zip(I.tolist(), J.tolist()))
    distinct = []
    for p in C.tolist():
        c = centre_vectors_few(p)
        distinct.append([distinct_few(c[i], c[j]) for i, j in pairs])
    return np.array(distinct, dtype=bool).reshape(M, len(pairs))
