"""The rank rule of a camera (:mod:`tritools.model.cameras`, check 2): sigma_3 / sigma_1 of the conditioned camera
and of its conditioned left 3 x 3 block, decided exactly below ``EXACT_RANK_BELOW``; its scalar twin for a few
cameras and its shared form for stacks that repeat their cameras; the power-of-two scalings they condition with."""
from __future__ import annotations

import math
from operator import mul

import numpy as np

from sospoly import pow2_above, pow2_above_array

from .regions.base import real_array

__all__ = ["CAMERA_RANK_RTOL", "EXACT_RANK_BELOW", "SHARED_MIN_CAMERAS", "camera_rank_ratio", "checked_rank_ratio",
           "rank_ratio_scalar", "shared_rank_ratio",
           "exactly_rank_deficient", "power2_scale", "unit_rows"]


#: A camera has rank < 3 if sigma_3 <= CAMERA_RANK_RTOL * sigma_1 for the conditioned camera
#: (see :func:`camera_rank_ratio`).
CAMERA_RANK_RTOL = 1e-10


def power2_scale(A: np.ndarray, axes: tuple) -> np.ndarray:
    """The power of two just above the largest absolute entry over ``axes`` (kept as size-1 axes;
    :func:`sospoly.pow2_above`), 1 where that entry is 0 or not finite.  Dividing by it is exact (barring
    underflow) and brings the entries into (-1, 1) -- (-2, 2) past 2^1023 -- so that later products and norms
    cannot overflow."""
    return pow2_above_array(np.maximum.reduce(np.abs(A), axis=axes, keepdims=True))   # (ndarray.max's ufunc)


def unit_rows(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R / ||R|| along the last axis, nonzero mask) for finite R; zero rows stay zero.  The rows
    are divided by a power of two near their largest entry first (exact), so nothing overflows."""
    S = R / power2_scale(R, (-1,))
    n = np.sqrt(np.sum(S * S, axis=-1, keepdims=True))
    return S / np.where(n > 0, n, 1.0), n[..., 0] > 0


def camera_rank_ratio(cameras) -> np.ndarray:
    """``sigma_3 / sigma_1`` of the conditioned camera(s), the quantity of the rank rule: the larger of the
    conditioned camera's and of its conditioned left 3 x 3 block's (the same conditioning on the block's rows; the
    camera has rank 3 if the block has).  The block matters for georeferenced cameras: a world translation of
    ~1e7 makes every row's fourth entry dominate, and the rows look parallel to ``CAMERA_RANK_RTOL``.

    For ``P`` with rows ``r1, r2, r3`` (after division by ``max |P_ij|``): ``u3 = r3 / ||r3||``,
    ``q_k = (r_k - (r_k.u3) u3) / ||.||`` (k = 1, 2, orthogonalised twice against ``u3``, ``r_k``
    scaled to unit norm first).  The rows of the conditioned matrix ``[q1; q2; u3]`` are unit vectors
    and ``q1, q2`` are orthogonal to ``u3``, so its singular values are ``sqrt(1 + |q1.q2|)``, 1,
    ``sqrt(1 - |q1.q2|)`` and

        sigma_3 / sigma_1 = ||q1 - s q2|| / ||q1 + s q2||,  s = sign(q1.q2),

    evaluated in this form (no cancellation).  It is 0 when ``r3 = 0`` or when ``r1`` or ``r2``
    has a component orthogonal to ``u3`` of at most ``CAMERA_RANK_RTOL`` times its norm.

    Parameters
    ----------
    cameras : array_like, shape (..., 3, 4)

    Returns
    -------
    ndarray, shape (...)
        NaN for a camera with a NaN or inf entry.
    """
    C = real_array(cameras, "cameras")
    if C.ndim < 2 or C.shape[-2:] != (3, 4):
        raise ValueError(f"cameras must have shape (..., 3, 4), got {C.shape}")
    return checked_rank_ratio(C)


def checked_rank_ratio(C: np.ndarray) -> np.ndarray:
    """:func:`camera_rank_ratio` of a float array (..., 3, 4) already checked: the larger of the conditioned
    camera's ratio and its conditioned left 3 x 3 block's (:func:`_conditioned_ratio` of both; NaN where an entry
    is not finite)."""
    ratio = np.fmax(_conditioned_ratio(C), _conditioned_ratio(C[..., :3]))
    flat, cams = np.atleast_1d(ratio).reshape(-1), C.reshape(-1, 3, 4)
    for k in np.flatnonzero((flat > 0) & (flat < EXACT_RANK_BELOW)):
        if exactly_rank_deficient(cams[k]):
            flat[k] = 0.0
    return flat.reshape(ratio.shape)


#: below this conditioned ratio the rank is also decided exactly (:func:`exactly_rank_deficient`): the conditioning
#: itself can lift an exactly rank-2 camera to ~1e-8 (review 8b F3: row 3 = 4 row 2 + row 1 in integers < 2^53)
EXACT_RANK_BELOW = 1e-4


def exactly_rank_deficient(P) -> bool:
    """Is the float 3 x 4 matrix P of rank < 3 in exact rational arithmetic (Gaussian elimination on Fractions)?"""
    from fractions import Fraction

    rows = [[Fraction(float(v)) for v in row] for row in np.asarray(P, float).tolist()]
    rank, col = 0, 0
    while rank < 3 and col < 4:
        pivot = next((r for r in range(rank, 3) if rows[r][col] != 0), None)
        if pivot is not None:
            rows[rank], rows[pivot] = rows[pivot], rows[rank]
            for r in range(rank + 1, 3):
                k = rows[r][col] / rows[rank][col]
                rows[r] = [a - k * b for a, b in zip(rows[r], rows[rank])]
            rank += 1
        col += 1
    return rank < 3


def _conditioned_ratio(C: np.ndarray) -> np.ndarray:
    """sigma_3 / sigma_1 of the conditioned rows of C (..., 3, k), k = 3 or 4 (the three rows scaled to unit norm
    in one :func:`unit_rows` call: the same operations, row by row)."""
    finite = np.isfinite(C).all(axis=(-2, -1))
    C = np.where(finite[..., None, None], C, 0.0)
    C = C / power2_scale(C, (-2, -1))
    rows, nonzero = unit_rows(C)
    u3 = rows[..., 2:3, :]
    # rows 1 and 2 at once (elementwise operations and sums along the last axis: the numbers of a row-by-row loop)
    r = rows[..., :2, :]
    p = r - np.add.reduce(r * u3, axis=-1, keepdims=True) * u3
    p = p - np.add.reduce(p * u3, axis=-1, keepdims=True) * u3           # twice is enough
    pn = np.sqrt(np.add.reduce(p * p, axis=-1))
    ok = nonzero[..., 2] & (nonzero[..., :2] & (pn > CAMERA_RANK_RTOL)).all(axis=-1)
    q = p / np.where(pn > 0, pn, 1.0)[..., None]
    q0, q1 = q[..., 0, :], q[..., 1, :]
    s = np.where(np.add.reduce(q0 * q1, axis=-1) < 0, -1.0, 1.0)[..., None]
    num = np.sqrt(np.add.reduce((q0 - s * q1) ** 2, axis=-1))
    den = np.sqrt(np.add.reduce((q0 + s * q1) ** 2, axis=-1))
    ratio = np.where(ok, num / np.where(den > 0, den, 1.0), 0.0)
    return np.where(finite, ratio, np.nan)


def rank_ratio_scalar(C: np.ndarray, decide_only: bool = False) -> list:
    """The scalar twin of :func:`checked_rank_ratio` for finite cameras (N, 3, 4): the same steps on Python floats
    (tests/test_cameras_scalar.py: equal to the vectorised rule within round-off).  ``decide_only``: a camera whose
    own conditioned ratio is at least ``EXACT_RANK_BELOW`` keeps that value without its left block's (the rule's
    value is the larger of the two, so it passes the rank test either way and needs no exact check): the same
    decisions, and the same value wherever the test fails, for half the work on ordinary cameras."""
    out = []
    for P in C.tolist():
        r = _conditioned_ratio_one(P)
        if not (decide_only and r >= EXACT_RANK_BELOW):
            r = max(r, _conditioned_ratio_one([row[:3] for row in P]))
        out.append(r)
    return [0.0 if 0 < r < EXACT_RANK_BELOW and exactly_rank_deficient(P) else r for r, P in zip(out, C)]


def _conditioned_ratio_one(P: list) -> float:
    """The scalar twin of :func:`_conditioned_ratio` for one finite camera or left block (three rows of floats).
    (Its sums are ``sum(map(mul, a, b))``: the order and operations of a sum over a generator, without its cost.)"""
    k = pow2_above(max(max(map(abs, P[0])), max(map(abs, P[1])), max(map(abs, P[2]))))
    rows, nonzero = [], []
    for row in P:
        row = [v / k for v in row]
        sr = pow2_above(max(map(abs, row)))
        row = [v / sr for v in row]
        n = math.sqrt(sum(map(mul, row, row)))
        rows.append([v / n for v in row] if n > 0 else row)
        nonzero.append(n > 0)
    u3 = rows[2]
    ps, pns = [], []
    for r in rows[:2]:
        d = sum(map(mul, r, u3))
        p = [a - d * b for a, b in zip(r, u3)]
        d = sum(map(mul, p, u3))
        p = [a - d * b for a, b in zip(p, u3)]
        pn = math.sqrt(sum(map(mul, p, p)))
        ps.append([v / pn for v in p] if pn > 0 else p)
        pns.append(pn)
    ok = nonzero[2] and all(nz and pn > CAMERA_RANK_RTOL for nz, pn in zip(nonzero[:2], pns))
    q0, q1 = ps
    sg = -1.0 if sum(map(mul, q0, q1)) < 0 else 1.0
    num = math.sqrt(sum([(a - sg * b) ** 2 for a, b in zip(q0, q1)]))
    den = math.sqrt(sum([(a + sg * b) ** 2 for a, b in zip(q0, q1)]))
    return num / (den if den > 0 else 1.0) if ok else 0.0


#: :func:`camera_problems` takes the rank ratio of each distinct camera once from this many cameras on (the tracks of
#: a model share their images' cameras: 40,000 tracks of 20 views hold 20, review 33a M1)
SHARED_MIN_CAMERAS = 4096
_KEY = np.random.default_rng(20261206).standard_normal(12)


def shared_rank_ratio(C: np.ndarray) -> np.ndarray:
    """:func:`camera_rank_ratio` of C (M, N, 3, 4), computed once per distinct camera where the stack repeats few
    (found by a random projection of the entries, then compared entry by entry: the same numbers)."""
    flat = C.reshape(-1, 12)
    if len(flat) < SHARED_MIN_CAMERAS:
        return camera_rank_ratio(C)
    with np.errstate(all="ignore"):
        _, first, inv = np.unique(flat @ _KEY, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    if 4 * len(first) > len(flat) or not (flat == flat[first][inv]).all():      # (NaN entries: never equal)
        return camera_rank_ratio(C)
    return camera_rank_ratio(flat[first].reshape(-1, 3, 4))[inv].reshape(C.shape[:-2])
