"""Which views share a camera centre, pairs of views stacked (issue #22: no Python loop over the N(N-1)/2 pairs).

The rule is :func:`tritools.model.geometry.fundamental_matrix`'s: with S_k = P_k / 2^(e_k) (each camera divided by a
power of two near its largest entry), a_j the unit null vector and S_j^+ the pseudo-inverse of S_j,

    F_ij = [e]_x S_i S_j^+,  e = S_i a_j,   the centres coincide iff ||F_ij||_F <= SAME_CENTER_RTOL ||S_i|| ||S_j||.

:func:`stacked_pair_tests` evaluates it for all pairs of a block of rows in three matrix products and decides a
pair only where the round-off of two evaluation orders cannot cross the threshold (the per-pair rule decides the
rest); :func:`merged_labels` replays the union of :func:`tritools.model.constraints.centre_groups_loop`.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from sospoly.budget import check_deadline

from .cameras import CAMERA_RANK_RTOL, camera_rank_ratio, power2_scale
from .geometry import SAME_CENTER_RTOL

__all__ = ["merged_labels", "group_pairs", "stackable", "stacked_pair_tests", "pair_fundamentals", "dot_norms",
           "skew_stack", "PAIR_BLOCK_ENTRIES", "PAIR_ROUNDOFF_UNITS", "PAIR_NORM_RTOL", "PAIR_CHUNK",
           "PAIR_RECHECK_RTOL"]


def merged_labels(N: int, pairs, start=None) -> np.ndarray:
    """The labels of :func:`~tritools.model.constraints.centre_groups_loop` for the pairs ``pairs`` (in combinations
    order) that share a centre: each pair moves the class of j to the label of i, as
    ``label[label == label[j]] = label[i]`` does, from the labels ``start`` (default ``arange(N)``)."""
    label = list(range(N)) if start is None else [int(v) for v in start]
    members: dict[int, list] = {}
    for v, lv in enumerate(label):
        members.setdefault(lv, []).append(v)
    for i, j in pairs:
        li, lj = label[i], label[j]
        if li != lj:
            moved = members.pop(lj)
            for v in moved:
                label[v] = li
            members[li] += moved
    return np.array(label, dtype=np.int_)


def stackable(C: np.ndarray) -> bool:
    """A finite float64 (N, 3, 4) stack whose cameras all pass :func:`~tritools.model.cameras.check_camera` by a
    margin (``camera_rank_ratio`` stacked: the same operations per camera; a factor 2 from the threshold)."""
    if C.dtype != np.float64 or C.ndim != 3 or C.shape[1:] != (3, 4) or not np.isfinite(C).all():
        return False
    return bool(np.all(camera_rank_ratio(C) > 2 * CAMERA_RANK_RTOL))


#: entries of one (rows, 3, columns, 3) block of :func:`stacked_pair_tests` (memory bounded at any N).
PAIR_BLOCK_ENTRIES = 2 ** 18
#: the round-off of two evaluations of ||F_ij|| apart (:func:`stacked_pair_tests`), in units of eps * ||W||_F.
PAIR_ROUNDOFF_UNITS = 32.0
#: relative slack for the rounding of the Frobenius norms (of F and of the cameras) in the threshold test.
PAIR_NORM_RTOL = 1e-12


def stacked_pair_tests(C: np.ndarray) -> tuple[list, list]:
    """(pairs i < j whose centres coincide by :func:`fundamental_matrix`'s rule, pairs too close to call), stacked.

    With S_k = P_k / 2^(e_k) (the power-of-two scaling of ``fundamental_matrix``), a_j the null vector and S_j^+
    the pseudo-inverse (batched SVDs: the same LAPACK calls per camera, so the same bits as the loop's),
    ``F_ij = [e]_x S_i S_j^+``, ``e = S_i a_j``, for all pairs of a block of rows in three matrix products.  Either
    evaluation order of these sums of <= 4 products (([e]_x S_i) S_j^+ in the loop, [e]_x (S_i S_j^+) here) is
    within ~7 u W entrywise of the exact value (u = eps / 2, first order), ``W = [|S_i| |a_j| + |e|]_x |S_i|
    |S_j^+|``, so the loop's ||F|| and this one are within 7 eps ||W||_F; ``PAIR_ROUNDOFF_UNITS * eps * ||W||_F``
    (a factor ~4 to spare) is the band, and a pair is decided here only when the band (and ``PAIR_NORM_RTOL`` for
    the norms' rounding) lies on one side of ``SAME_CENTER_RTOL ||S_i|| ||S_j||``."""
    N = C.shape[0]
    S = C / power2_scale(C, (1, 2))
    a = np.linalg.svd(S)[2][:, -1]
    pinv = np.linalg.pinv(S)
    nP = np.sqrt(np.sum(S * S, axis=(1, 2)))
    rows = max(1, PAIR_BLOCK_ENTRIES // (9 * N))
    same, unsure = [], []
    for i0 in range(0, N - 1, rows):
        check_deadline("comparing the camera centres")
        i1 = min(N - 1, i0 + rows)
        nrm, err = _pair_block(S[i0:i1], a[i0:], pinv[i0:])
        T = SAME_CENTER_RTOL * nP[i0:i1, None] * nP[None, i0:]
        below = (nrm + err) * (1 + PAIR_NORM_RTOL) < T * (1 - PAIR_NORM_RTOL)      # the loop's ||F|| <= its T
        above = (nrm - err) * (1 - PAIR_NORM_RTOL) > T * (1 + PAIR_NORM_RTOL)      # the loop's ||F|| > its T
        upper = np.arange(i0, i1)[:, None] < np.arange(i0, N)[None, :]
        same += _pair_list(below & upper, i0)
        unsure += _pair_list(~below & ~above & upper, i0)                        # (NaN: neither)
    return same, unsure


def _pair_list(mask: np.ndarray, i0: int) -> list:
    """The pairs (i0 + row, i0 + column) where ``mask`` holds, in row-major (combinations) order."""
    I, J = np.nonzero(mask)
    return list(zip((I + i0).tolist(), (J + i0).tolist()))


def _pair_block(Si: np.ndarray, a: np.ndarray, pinv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(||F_ij||_F, its round-off band) for the rows Si (b, 3, 4) against the columns' null vectors a (n, 4) and
    pseudo-inverses pinv (n, 4, 3) (:func:`stacked_pair_tests`), each (b, n); NaN where not finite."""
    b, n = Si.shape[0], a.shape[0]
    R, Ra = Si.reshape(3 * b, 4), np.abs(Si).reshape(3 * b, 4)
    PT = np.swapaxes(pinv, 0, 1).reshape(4, 3 * n)                  # PT[k, 3j + c] = pinv_j[k, c]
    with np.errstate(all="ignore"):
        e = (R @ a.T).reshape(b, 3, n)                              # e[i, :, j] = S_i a_j
        s = (Ra @ np.abs(a).T).reshape(b, 3, n) + np.abs(e)
        M = (R @ PT).reshape(b, 3, n, 3)                            # M[i, :, j, :] = S_i S_j^+
        Q = (Ra @ np.abs(PT)).reshape(b, 3, n, 3)
        F2 = np.zeros((b, n))
        W2 = np.zeros((b, n))
        for r in range(3):                                          # row r of [e]_x M: e_p M_q - e_q M_p
            p, q = (r + 1) % 3, (r + 2) % 3
            Fr = e[:, p, :, None] * M[:, q] - e[:, q, :, None] * M[:, p]
            Wr = s[:, p, :, None] * Q[:, q] + s[:, q, :, None] * Q[:, p]
            F2 += np.sum(Fr * Fr, axis=2)
            W2 += np.sum(Wr * Wr, axis=2)
    return np.sqrt(F2), PAIR_ROUNDOFF_UNITS * np.finfo(float).eps * np.sqrt(W2)


#: pairs per chunk of :func:`pair_fundamentals` (memory bounded at any N).
PAIR_CHUNK = 4096
#: :func:`pair_fundamentals` leaves a pair to the per-pair rule when ||F|| is within this fraction of the threshold.
PAIR_RECHECK_RTOL = 1e-6


def pair_fundamentals(C: np.ndarray, I: np.ndarray, J: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``fundamental_matrix(C[I[k]], C[J[k]])`` for the pairs k of a :func:`stackable` stack C (N, 3, 4), stacked:
    (F (K, 3, 3) of unit norm, 0 where undefined; defined (K,): False where the per-pair function raises "same
    camera centre"; recheck (K,): pairs whose ||F|| lies within ``PAIR_RECHECK_RTOL`` of the threshold, which the
    caller decides pair by pair).

    The operations of :func:`~tritools.model.geometry.fundamental_matrix` per pair, each over the stack: the batched
    SVDs and matrix products make the same LAPACK / BLAS call per matrix as the single ones, and ``np.linalg.norm``'s
    dot product is a (1, 9) @ (9, 1) product per pair (:func:`dot_norms`), so the same numbers (tested equal)."""
    S = C / power2_scale(C, (1, 2))
    a = np.linalg.svd(S)[2][:, -1]
    pinv = np.linalg.pinv(S)
    nP = dot_norms(S.reshape(len(S), -1))
    K = len(I)
    F, defined, recheck = np.zeros((K, 3, 3)), np.zeros(K, bool), np.zeros(K, bool)
    for k0 in range(0, K, PAIR_CHUNK):
        check_deadline("computing the fundamental matrices")
        i, j = I[k0:k0 + PAIR_CHUNK], J[k0:k0 + PAIR_CHUNK]
        Pi = S[i]
        G = skew_stack(np.matmul(Pi, a[j][..., None])[..., 0]) @ Pi @ pinv[j]
        nrm = dot_norms(G.reshape(len(G), 9))
        T = SAME_CENTER_RTOL * nP[i] * nP[j]
        ok = ~(nrm <= T)
        F[k0:k0 + len(i)][ok] = G[ok] / nrm[ok, None, None]
        defined[k0:k0 + len(i)] = ok
        recheck[k0:k0 + len(i)] = ~(np.abs(nrm - T) > PAIR_RECHECK_RTOL * T)
    return F, defined, recheck


def dot_norms(A: np.ndarray) -> np.ndarray:
    """``[np.linalg.norm(a) for a in A]`` for rows A (K, n): sqrt of each row's dot product with itself, one
    (1, n) @ (n, 1) product per row (the dot product ``np.linalg.norm`` takes of a flattened array)."""
    R = A[:, None, :]
    return np.sqrt(np.matmul(R, np.swapaxes(R, 1, 2))[:, 0, 0])


def skew_stack(e: np.ndarray) -> np.ndarray:
    """[e]_x for vectors e (K, 3): (K, 3, 3), entry for entry :func:`tritools.model.geometry._skew`."""
    out = np.zeros(e.shape + (3,))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -e[:, 2], e[:, 1], -e[:, 0]
    out[:, 1, 0], out[:, 2, 0], out[:, 2, 1] = e[:, 2], -e[:, 1], e[:, 0]
    return out


def group_pairs(groups) -> list:
    """The pairs (i < j) with ``groups[i] == groups[j]``, in combinations order: a loop over the members of each
    group, not over all N(N-1)/2 pairs."""
    g = np.asarray(groups)
    values, counts = np.unique(g, return_counts=True)
    out = []
    for v in values[counts > 1]:
        out += combinations(np.flatnonzero(g == v).tolist(), 2)
    out.sort()
    return out
