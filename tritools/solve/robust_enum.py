"""Certified TLS for a few views by subset enumeration: the maths of one stacked verification of every inlier set.

This module holds the pieces, each stacked over rows (and problems): the frames (:func:`enum_frames`), the masked
candidates (:func:`enum_candidates`), the bounds (:func:`enum_bounds_rows`) and the superadditive closure
(:func:`closure`); :mod:`tritools.solve.robust_enum_run` runs them for one search or a batch of them.

For thresholds c_i and point regions (:mod:`tritools.solve.robust`),

    f*_TLS = min over subsets S of [ L2*(S) + c^2(V - S) ],     L2*(S) = min_X sum_{i in S} d_i(X)^2,

with L2*(S) = 0 for |S| <= 1.  For N <= :data:`ENUM_MAX_VIEWS` views there are at most 2^N - N - 1 subsets
with |S| >= 2 (N = 3: 4; N = 5: 26; N = 8: 247), few enough to bound *every* one in a few stacked calls
(:mod:`tritools.solve.robust_enum_run`) instead of a branch and bound with several rounds of sub-problems.  Each
subset is one row of a stack of N-view problems in one normalised frame of the whole problem (:func:`enum_frames`:
x' = s (x - x_i), X = X_0 + d X'); a view outside S is masked:

* its camera is replaced by ``MASKED_CAMERA`` = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]] for the candidate
  (its projection is the origin for every X, where its observation sits: residual and Jacobian 0), so the
  DLT of the row is the DLT of S and the Levenberg-Marquardt polish (:data:`POLISH_STEPS`) minimises
  sum_{i in S} ||Phi(X', P'_i)||^2 only;
* for the bound (:func:`enum_bounds`: the fundamental matrices of the N views computed once, then
  :func:`sospoly.analysis.verify_quadratic_batch`, the Lagrangian bound of
  :func:`tritools.solve.fastpath.lagrangian_bounds`), its epipolar constraints are dropped (their F set to 0,
  as ``views`` does there) and its image variables are set to 0 in the candidate:
  they are then free and unconstrained in min sum_k v_k^2, whose minimiser has them at 0, so the program is
  the degree-2 program of S (Corollary 1 at delta = 2, SPEC §7) and its Lagrangian bound c'(S) is rigorous at
  any candidate, with the radius ||v^|| (v^ is the projection of a point: feasible, f(v*) <= ||v^||^2).

As in :mod:`tritools.solve.robust_verify`, L2*(S) = L2'*(S) / s^2 for every S, so
L2LB(S) = max(0, min(c'(S), ||v^||^2)) / s^2, rounded down.  Bounds are then closed under superadditivity
(:func:`closure`): L2*(S) >= L2*(T) + L2*(S - T) for every split of S (monotonicity is the split with a
single view), so a subset whose own Lagrangian bound is weak (typically one holding a wrong match) inherits
the bounds of its parts.  The lower bound

    LB = min( UB, min over S of (L2LB(S) + c^2(V - S)) ),   |S| <= 1 and S missing an infinite c: exact terms,

is valid under floating point (every sum rounded down).  The upper bound UB is the exact f_TLS of the best row
candidate X_S (world frame).  Where LB and UB meet under the certificate rule of :mod:`tritools.solve.robust`
(:meth:`TlsSearch.result`, the one decision rule: ``sospoly.Tolerances`` at ``robust.decision_scale``) the
result is returned; elsewhere (a weak bound that no split repairs, an optimum on a single view's ray, degenerate
data) the run returns None and the caller runs the branch and bound, which starts from the best
candidate found here.

The decision scale.  ``decision_scale`` needs the L2 normalisation of the whole problem (a Levenberg-Marquardt
run from the DLT point, ~1 ms with a wrong match in the track: more than the rest of this path).  Its value is
never below ``robust.scale_from(SCALE_BOUNDS[1], c^2)`` (the normalisation clips s to SCALE_BOUNDS), and the
certificate rule is monotone in the scale, so where the bounds meet at that floor and do not contradict there,
they meet at the documented scale too: the result is the documented rule's, without the normalisation.  Only
elsewhere is the documented scale computed.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from sospoly.analysis import ascend_one, bound_at_one, verify_quadratic_batch

from ..model.cameras import power2_scale
from ..model.epipolar_data import epipolar_errors
from ..model.exact import dot2, dot2_one, homogeneous_images
from ..model.lm_one import refine_point_one
from ..model.normalize import RHO_FLOOR_REL, SCALE_BOUNDS, Normalization
from ..model.stacked import (dlt_stack, epipolar_quadratics, fundamental_stack_both, gauss_newton_polish,
                             median_rows, norms, null_vectors, pixel_scales, project_one, project_stack,
                             refine_points_stack, view_pairs)
from .robust_bounds import ROUND_DOWN
from .robust_verify import polish_rows

__all__ = ["enum_frame", "enum_frame_one", "enum_frames", "subset_masks", "closure", "enum_candidates", "enum_bounds",
           "enum_bounds_rows", "fundamentals", "row_of", "subset_of", "refine_rows", "refine_row_one", "ascended_bound",
           "first_of_runs", "ENUM_MAX_VIEWS", "POLISH_STEPS", "MASKED_CAMERA", "ENUMERATED", "ASCENT_HEADROOM"]

#: the enumeration runs for point problems with at most this many views in single calls (the branch and bound
#: beyond; batches: :data:`tritools.solve.robust_batch.BATCH_ENUM_MAX_VIEWS`, 10 views, 1013 sets).  Measured
#: (CVPR 2023 protocol, c = 200 px, 1 px, 12 scenes per cell, median CPU of the search over the enumeration, the two
#: interleaved): with 20% / 40% wrong matches 2.1 / 1.6 at N = 7, 1.5 / 1.3 at N = 8, 1.2 / 0.8 at N = 9 (0.4 / 0.3
#: at N = 10 before the two-stack candidates); clean tracks 0.8-0.9 at N = 7-9 (the search's root certificate).
ENUM_MAX_VIEWS = 8
#: Levenberg-Marquardt steps polishing each row's DLT start.
POLISH_STEPS = 5
#: :func:`closure` runs over at most this many problems at a time (its gathers of (splits, problems) then stay in
#: cache: measured at N = 10, 200 problems, 0.07 s in one call, 0.027 s in chunks of 16, 0.054 s of 64).
CLOSURE_CHUNK = 16
#: a masked view's camera: Phi(X, P) = (0, 0) for every X (module docstring).
MASKED_CAMERA = np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
#: the result's message says this when the enumeration decided it.
ENUMERATED = "every inlier set enumerated"


@functools.lru_cache(maxsize=16)
def subset_masks(N: int) -> np.ndarray:
    """Every subset of the N views with at least 2 views, as rows of an (M, N) bool array, by size then
    lexicographically (read-only).  Among subsets of one size, the lexicographic order of the sorted index tuples
    is the descending order of the indicator rows read with view 0 most significant (the first index where two
    tuples differ is the first position where the indicators do, held by the smaller tuple only)."""
    bits = np.arange(1 << N)
    ind = ((bits[:, None] >> np.arange(N)) & 1).astype(bool)
    size = ind.sum(axis=1)
    key = ind.astype(np.int64) @ (1 << np.arange(N - 1, -1, -1))
    order = np.lexsort((-key, size))
    out = ind[order[size[order] >= 2]]
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=16)
def _splits(N: int) -> tuple:
    """Per subset size k >= 2: (the bit masks of the subsets S of size k, the bit masks T and S - T of every split
    of such S into two non-empty parts with T the part holding S's lowest view, the index of each S's first split:
    the splits of one S are contiguous, in the order of the S).  Vectorised: T = lowest view | any proper subset of
    the k - 1 others (2^(k-1) - 1 splits per S)."""
    W = subset_masks(N)
    size = W.sum(axis=1)
    out = []
    for k in range(2, N + 1):
        Wk = W[size == k]
        idx = np.nonzero(Wk)[1].reshape(len(Wk), k)            # each S's views, ascending
        S = (1 << idx).sum(axis=1)
        r = np.arange((1 << (k - 1)) - 1)                      # proper subsets of the other k - 1 views
        pick = (r[:, None] >> np.arange(k - 1)) & 1            # (2^(k-1) - 1, k - 1)
        T = ((1 << idx[:, :1]) + (1 << idx[:, 1:]) @ pick.T).reshape(-1)    # (S, split), S-major
        R = np.repeat(S, len(r)) ^ T
        out.append((S, T, R, np.arange(len(Wk)) * len(r)))
    return tuple(out)


def closure(N: int, lb_by_bits: np.ndarray) -> np.ndarray:
    """The superadditive closure of subset bounds indexed by bit mask (..., 2^N; entries of |S| <= 1 are 0; a
    leading axis holds problems): L(S) = max(L(S), max over splits S = T + R of (L(T) + L(R)) rounded down), by
    increasing size, so the parts are closed first.  Valid: L2*(S) >= L2*(T) + L2*(R) for disjoint T, R (each term
    of the sum over S is a term of one part, each part's L2* is a minimum over X)."""
    lb = np.asarray(lb_by_bits, float)
    if lb.ndim == 2 and len(lb) > CLOSURE_CHUNK:       # a few problems at a time: the gathers stay in cache
        return np.concatenate([closure(N, lb[k:k + CLOSURE_CHUNK]) for k in range(0, len(lb), CLOSURE_CHUNK)])
    L = np.array(np.moveaxis(lb, -1, 0))                # subsets first: the gathers take rows
    for S, T, R, starts in _splits(N):
        best = np.maximum.reduceat((L[T] + L[R]) * ROUND_DOWN, starts, axis=0)
        L[S] = np.maximum(L[S], best)
    return np.moveaxis(L, 0, -1)


def enum_frame(C: np.ndarray, x: np.ndarray, c2: np.ndarray | None = None):
    """:func:`enum_frames` of one problem (cameras C (N, 3, 4), points x (N, 2), squared thresholds c2 (N,) or None):
    (Normalization, Cn (N, 3, 4)) or None; up to :data:`FRAME_SCALAR_MAX_VIEWS` views by the scalar twin
    :func:`enum_frame_one`."""
    if len(x) <= FRAME_SCALAR_MAX_VIEWS:
        return enum_frame_one(C, x, c2)
    frames, Cn = enum_frames(C[None], x[None], None if c2 is None else np.asarray(c2, float)[None])
    return None if frames[0] is None else (frames[0], Cn[0])


#: :func:`enum_frame` takes the scalar twin up to this many views (numpy's sums over the views are sequential below
#: 8 terms, so the twin's sums are numpy's).
FRAME_SCALAR_MAX_VIEWS = 7


def enum_frame_one(C: np.ndarray, x: np.ndarray, c2: np.ndarray | None = None):
    """The scalar twin of :func:`enum_frames` for one problem (cameras C (N, 3, 4), points x (N, 2)): the same steps,
    the camera centres, their mean c0, the compensated last columns of the cameras moved to c0 and the frame's
    scalars on Python floats, the DLT, the floor's pixel scales and the normalised cameras on the problem's small
    arrays -- equal to the stack of one up to round-off (tests/test_enum_frame_twin.py).  (Normalization, Cn) or
    None where the stacked rule gives None."""
    N = len(x)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        C = C / power2_scale(C, (1, 2))
        a = null_vectors(C)
        an = norms(a, axis=1)
        if not (np.abs(a[:, 3]) > 1e-12 * an).all():
            return None                                     # a centre at infinity
        centres = (a[:, :3] / a[:, 3:]).tolist()
        sx = sy = sz = 0.0
        for cx, cy, cz in centres:                          # np.add.reduce over the views: in view order
            sx, sy, sz = sx + cx, sy + cy, sz + cz
        c0 = [sx / N, sy / N, sz / N]
        Cc = C.copy()
        Cc[:, :, 3] = [[dot2_one(row[:3], c0, row[3]) for row in P] for P in C.tolist()]     # (dot2's bits)
        X0, good = dlt_stack(Cc[None], x[None])
        X0 = X0[0]
        if not (good[0] and np.isfinite(X0).all()):
            return None
        u, _, fin = project_one(Cc, X0)
        if not fin:
            return None
        X0l = X0.tolist()
        dist = sorted(math.sqrt((cx - c0[0] - X0l[0]) ** 2 + (cy - c0[1] - X0l[1]) ** 2 + (cz - c0[2] - X0l[2]) ** 2)
                      for cx, cy, cz in centres)
        d = dist[(N - 1) // 2] if N % 2 else (dist[N // 2 - 1] + dist[N // 2]) / 2
        rho = math.sqrt(float(np.add.reduce((u - x) ** 2, axis=None)) / N)
        if c2 is not None and N > 2:                        # (enum_frames' rule, two views uncapped)
            r2 = np.add.reduce((u - x) ** 2, axis=1)
            cap = FRAME_CAP2 * np.asarray(c2, float)
            if (r2 > cap).any():
                rho = math.sqrt(float(np.add.reduce(np.minimum(r2, cap))) / N)
        B = C[:, :2, :3] - x[:, :, None] * C[:, 2:3, :3]
        top = norms(B, axis=(1, 2)) / norms(C[:, 2, :3], axis=1)
        if not rho > RHO_FLOOR_REL * float(np.max(top)):
            ps = pixel_scales(C[None], x[None])[0]
            ps = ps[np.isfinite(ps) & (ps > 0)]
            rho = max(rho, RHO_FLOOR_REL * float(np.median(ps)) if ps.size else 0.0)
        if not (math.isfinite(d) and d > 0 and math.isfinite(rho) and rho > 0):
            return None
        s = min(max(1.0 / rho, SCALE_BOUNDS[0]), SCALE_BOUNDS[1])
        CH = np.empty_like(C)
        CH[:, :, :3] = C[:, :, :3] * d
        CH[:, :, 3] = homogeneous_images(Cc, np.append(X0, 1.0))
        Cn = CH.copy()
        Cn[:, :2] = s * (CH[:, :2] - x[..., None] * CH[:, 2:3])
        Cn /= norms(Cn, axis=(1, 2))[:, None, None]
        if not np.isfinite(Cn).all():
            return None
        terms = (np.maximum(np.abs(Cc[:, 0, 3]), np.abs(Cc[:, 1, 3])) + np.max(np.abs(x), axis=1) * np.abs(Cc[:, 2, 3]),
                 Cc[:, 2, :].copy(), np.array(c0), np.abs(CH[:, 2, 3]))
    return Normalization(s, x, np.array(c0) + X0, d, frame_terms=terms), Cn


#: the enumeration frame's residuals are capped at FRAME_CAP2 c_i^2 (:func:`enum_frames`): a wrong match far off the
#: image then no longer sets the unit of the inliers' bounds (which lost ~u / s^2 px^2: 1e-5 of f at 1e6 px, review
#: 48a F1), while the sets holding it keep coordinates of at most ~sqrt(FRAME_CAP2) times their magnitude / c, where
#: their Lagrangian bounds still hold (capped at c^2 itself, a wrong match 1e7 px off sat at 2e6 units and its sets'
#: bounds failed: the term of the inliers then did not decide)
FRAME_CAP2 = 1e6


def enum_frames(C: np.ndarray, x: np.ndarray, c2: np.ndarray | None = None) -> tuple:
    """Normalisations of P point problems of N views (cameras C (P, N, 3, 4), points x (P, N, 2)) without the local
    refinement of :func:`tritools.model.normalize.normalization_for`: X_0 the DLT point (solved in a world
    translated to the mean camera centre), d the median distance to the camera centres, s = 1 / rho with rho the
    RMS residual of X_0 (each view's squared residual capped at ``FRAME_CAP2`` times its squared threshold c2 (P, N)
    where given and exceeded, from three views on: two views with a wrong match have an inlier set of one view, whose
    term is exact, and the cap only moved the two-view path's candidates, review 49b M2;
    floored at ``RHO_FLOOR_REL`` times the median pixel scale, s clipped to
    ``SCALE_BOUNDS``).  Any frame gives exact identities (module docstring); this one only conditions the numbers.
    Returns (a list of P :class:`Normalization` or None where one cannot be formed -- the caller runs the search,
    whose normalisation handles degenerate data --, the normalised cameras Cn (P, N, 3, 4))."""
    P, N = x.shape[:2]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        C = C / power2_scale(C, (2, 3))                 # exact: a georeferenced centre stays where it is
        a = null_vectors(C)
        ok = ~np.any(np.abs(a[..., 3]) <= 1e-12 * norms(a, axis=2), axis=1)     # no centre at infinity
        centres = a[..., :3] / a[..., 3:]
        # the DLT in a world centred on the cameras (c0 their mean, np.mean's operations): georeferenced
        c0 = np.add.reduce(centres, axis=1) / N
        Cc = C.copy()                                   # coordinates (1e6 m) would drown its linear system;
        c0b = np.broadcast_to(np.where(ok[:, None], c0, 0.0)[:, None, None, :], C.shape[:3] + (3,))
        Cc[..., 3] = dot2(C[..., :3], c0b, C[..., 3])   # compensated: the frame is the caller's problem exactly
        X0, good = dlt_stack(Cc, x)
        ok &= good & np.isfinite(X0).all(axis=1)
        X0 = np.where(ok[:, None], X0, 0.0)
        u, _, fin = project_stack(Cc, X0)
        ok &= fin
        d = median_rows(norms(centres - c0[:, None] - X0[:, None], axis=2))
        rho = np.sqrt(np.sum((u - x) ** 2, axis=(1, 2)) / N)
        if c2 is not None and N > 2:
            r2 = np.add.reduce((u - x) ** 2, axis=2)
            cap = FRAME_CAP2 * c2
            capped = (r2 > cap).any(axis=1)
            rho = np.where(capped, np.sqrt(np.add.reduce(np.minimum(r2, cap), axis=1) / N), rho)
        # the floor (zero noise): pixel scales are at most ||P[:2, :3] - x P[2, :3]||_F / ||P[2, :3]||, computed
        # only where that bound does not already put the floor below rho
        B = C[..., :2, :3] - x[..., None] * C[..., 2:3, :3]
        top = norms(B, axis=(2, 3)) / norms(C[..., 2, :3], axis=2)
        for p in np.nonzero(ok & ~(rho > RHO_FLOOR_REL * np.max(top, axis=1)))[0]:
            ps = pixel_scales(C[p:p + 1], x[p:p + 1])[0]
            ps = ps[np.isfinite(ps) & (ps > 0)]
            rho[p] = max(rho[p], RHO_FLOOR_REL * float(np.median(ps)) if ps.size else 0.0)
        ok &= np.isfinite(d) & (d > 0) & np.isfinite(rho) & (rho > 0)
        s = np.minimum(np.maximum(1.0 / rho, SCALE_BOUNDS[0]), SCALE_BOUNDS[1])
        # P'_i = T_i P_i H / ||.||_F (Normalization.cameras, vectorised):
        # T_i = [[s, 0, -s x_i], [0, s, -s y_i], [0, 0, 1]]
        Xh = np.concatenate([X0, np.ones((P, 1))], axis=1)
        CH = np.concatenate([C[..., :3] * d[:, None, None, None],
                             homogeneous_images(Cc, Xh)[..., None]], axis=3)
        Cn = CH.copy()
        Cn[:, :, :2] = s[:, None, None, None] * (CH[:, :, :2] - x[..., None] * CH[:, :, 2:3])
        Cn /= norms(Cn, axis=(2, 3))[..., None, None]
        ok &= np.isfinite(Cn).all(axis=(1, 2, 3))
    frames = [Normalization(float(s[p]), x[p], c0[p] + X0[p], float(d[p])) if ok[p] else None for p in range(P)]
    return frames, Cn


def enum_candidates(Cn: np.ndarray, W: np.ndarray, steps: int | None = None, by_size: bool = False) -> np.ndarray:
    """Normalised candidates Xn (M, 3) (NaN where not finite) of the subsets ``W`` (M, N) of the views of the
    normalised cameras Cn ((N, 3, 4) shared by every row, or (M, N, 3, 4): each row its own problem's): the DLT of
    each subset polished by ``steps`` (default :data:`POLISH_STEPS`) Levenberg-Marquardt steps, all in one masked
    stack (module docstring); ``by_size`` (stacks of many rows): one stack per subset size on the subsets' own views
    (the same programs, k / N of the cost)."""
    M, N = W.shape
    steps = POLISH_STEPS if steps is None else steps
    if not by_size:
        Cm = np.where(W[:, :, None, None], Cn, MASKED_CAMERA)
        X0, ok = dlt_stack(Cm, np.zeros((M, N, 2)))
        Xn = polish_rows(Cm, np.where(ok[:, None] & np.isfinite(X0), X0, 0.0), steps)
        return np.where(np.isfinite(Xn).all(axis=1)[:, None], Xn, np.nan)
    Cb = np.broadcast_to(Cn, (M,) + Cn.shape[-3:])
    size = W.sum(axis=1)
    out = np.full((M, 3), np.nan)
    for k in np.unique(size):               # per subset size, on the subset's views only: a masked view adds a zero
        r = np.nonzero(size == k)[0]        # DLT row, residual and Jacobian (module docstring), so this is the
        Cm = Cb[r[:, None], np.nonzero(W[r])[1].reshape(len(r), k)]     # masked stack's program at k / N the cost
        X0, ok = dlt_stack(Cm, np.zeros((len(r), k, 2)))
        Xn = polish_rows(Cm, np.where(ok[:, None] & np.isfinite(X0), X0, 0.0), steps)
        out[r] = np.where(np.isfinite(Xn).all(axis=1)[:, None], Xn, np.nan)
    return out


def refine_rows(Cn: np.ndarray, X0: np.ndarray, inS: np.ndarray, scalar: bool | None = None) -> tuple:
    """(Xn (R, 3), ok (R,)): normalised candidates X0 (R, 3) refined to convergence on their inlier sets ``inS``
    (R, N) by :func:`tritools.model.stacked.refine_points_stack` and one Gauss-Newton step (a row's few polish
    steps leave the L2 optimum of a set short by ~1e-6 in X, though not in f; the step finishes a weak direction
    the damped LM left, tiny baselines), the views outside the set masked; Cn (R, N, 3, 4) each row's normalised
    cameras (observations at the origin).  A stack of one row (a single call): :func:`refine_row_one`; ``scalar``
    False: the stacked code for any number of rows (a batch: each row's numbers then do not depend on how many rows
    its stack has, review 19 F4; the twins agree only up to round-off)."""
    if (len(X0) == 1) if scalar is None else scalar:
        Xn, ok = refine_row_one(Cn[0], X0[0], np.flatnonzero(inS[0]).tolist())
        return Xn[None], np.array([ok])
    Cm = np.where(inS[:, :, None, None], Cn, MASKED_CAMERA)
    zeros = np.zeros(inS.shape + (2,))
    Xn, ok = refine_points_stack(Cm, zeros, X0, np.ones(len(X0), bool), scalar=False)
    Xn = gauss_newton_polish(Cm, zeros, Xn, ok, scalar=False)
    return Xn, ok & np.isfinite(Xn).all(axis=1)


def refine_row_one(Cn: np.ndarray, X0: np.ndarray, views: list) -> tuple:
    """The scalar twin of :func:`refine_rows` for one row (:func:`tritools.model.lm_one.refine_point_one` on Python
    floats): (Xn (3,), ok) for one problem's normalised cameras Cn (N, 3, 4), a start X0 (3,) and its set's views
    (ascending).  The masked views are left out: their residual and Jacobian are 0 at every X, terms that add
    nothing.  Equal to :func:`refine_rows` up to round-off (tests/test_single_call_twins.py)."""
    C = Cn.tolist()
    X, ok, _ = refine_point_one([C[i] for i in views], [(0.0, 0.0)] * len(views), X0.tolist())
    return np.array(X), ok


def fundamentals(C: np.ndarray, Cn: np.ndarray) -> tuple:
    """(F (P, K, 3, 3), defined (P, K), E (P, K)) of the view pairs of P problems in their normalised frames Cn
    (P, N, 3, 4), with coincident centres decided on the raw cameras C (P, N, 3, 4) too, and E the proven errors of
    the computed F (:func:`tritools.model.stacked.fundamental_stack`'s ``errors``): computed once per problem, for
    every subset bound of :func:`enum_bounds_rows` and :func:`ascended_bound` (a subset's pairs gather them)."""
    F, defined, raw, E = fundamental_stack_both(Cn, C)
    return F, defined & raw, E


def enum_bounds(C: np.ndarray, Cn: np.ndarray, W: np.ndarray, Xn: np.ndarray, s: float, tolerances):
    """:func:`enum_bounds_rows` of one problem (cameras C (N, 3, 4), normalised Cn, frame scale s)."""
    F, defined, E = fundamentals(C[None], Cn[None])
    M = len(W)
    return enum_bounds_rows(np.broadcast_to(Cn, (M,) + Cn.shape), np.broadcast_to(F[0], (M,) + F.shape[1:]),
                            np.broadcast_to(defined[0], (M,) + defined.shape[1:]), W, Xn, np.full(M, s), tolerances,
                            errors=np.broadcast_to(E[0], (M,) + E.shape[1:]))


def enum_bounds_rows(Cn, F, defined, W: np.ndarray, Xn: np.ndarray, s: np.ndarray, tolerances, problem=None,
                     by_size: bool = False, accepted: bool = True, errors=None):
    """(L2 lower bounds (M,) pixels^2, accepted (M,)) of the subsets ``W`` (M, N) at the normalised candidates Xn
    (M, 3), each row with its problem's normalised cameras Cn (M, N, 3, 4), fundamental matrices F (M, K, 3, 3) and
    ``defined`` (M, K) (:func:`fundamentals`; with ``problem`` (M,): F (P, K, 3, 3) and ``defined`` (P, K) per
    problem, row m's problem ``problem[m]``, so that only its subset's pairs are gathered), F's proven errors
    ``errors`` shaped as ``defined`` (:func:`fundamentals`' E; None: computed from Cn) and frame scale s (M,)
    (module docstring): the Lagrangian bound of
    the degree-2 program of each subset, the epipolar constraints of its view pairs only.  ``accepted``: the bound
    meets the candidate's value under the certificate rule at the subset's residual scale (as
    :func:`tritools.solve.robust_verify.verify_in_parent` accepts a bound); None with ``accepted=False`` (the
    enumeration reads the bounds only).

    ``by_size`` (stacks of many rows): the rows are bounded per subset size k on the k views of their subsets only
    (:func:`_subset_bounds`): the masked views' image variables are free in sum_k v_k^2 and in no constraint, so
    the program of a row is the k-view program exactly (a pair: 4 variables and 1 constraint instead of 2N and
    N(N-1)/2).  Else one masked stack of N views (fewer calls: a single problem's few rows)."""
    M, N = W.shape
    if not by_size:
        if problem is not None:
            F, defined = F[problem], defined[problem]
            errors = None if errors is None else errors[problem]
        return _masked_bounds(Cn, F, defined, W, Xn, s, tolerances, accepted, errors)
    size = W.sum(axis=1)
    lb, ok = np.zeros(M), np.zeros(M, bool)
    for k in np.unique(size):
        r = np.nonzero(size == k)[0]
        views = np.nonzero(W[r])[1].reshape(len(r), k)       # each row's views, ascending
        Ik, Jk = view_pairs(int(k))
        pair = _pair_index(N)[views[:, Ik], views[:, Jk]]     # (R, k(k-1)/2): their pairs' rows of F
        owner = (r if problem is None else problem[r])[:, None]
        lb[r], acc = _subset_bounds(Cn[r[:, None], views], F[owner, pair], defined[owner, pair], Xn[r], s[r],
                                    tolerances, accepted, None if errors is None else errors[owner, pair])
        if accepted:
            ok[r] = acc
    return lb, (ok if accepted else None)


@functools.lru_cache(maxsize=16)
def _pair_index(N: int) -> np.ndarray:
    """(N, N): the index of the pair (i, j), i < j, in :func:`view_pairs` (N) (-1 elsewhere; read-only)."""
    I, J = view_pairs(N)
    out = np.full((N, N), -1)
    out[I, J] = np.arange(len(I))
    out.flags.writeable = False
    return out


def _masked_bounds(Cn, F, defined, W: np.ndarray, Xn: np.ndarray, s: np.ndarray, tolerances, accepted=True,
                   errors=None):
    """:func:`enum_bounds_rows` in one masked stack of N views (a view outside a row's subset: its image variables
    0 in the candidate, its epipolar constraints dropped)."""
    M, N = W.shape
    u, _, fin = project_stack(Cn, Xn)
    fin &= np.isfinite(Xn).all(axis=1)
    v = np.where(W[:, :, None] & fin[:, None, None], u, 0.0).reshape(M, -1)
    I, J = view_pairs(N)
    held = W[:, I] & W[:, J] & defined
    return _verified(v, fin, np.where(held[..., None, None], F, 0.0), N, s, tolerances, W.sum(axis=1), accepted,
                     Cn, errors)


def _verified(v, fin, F, N: int, s, tolerances, size, accepted=True, Cn=None, errors=None):
    """The bounds and acceptance of :func:`enum_bounds_rows` from the rows' image candidates v (M, 2N), finiteness
    ``fin`` and the fundamental matrices F (M, N(N-1)/2, 3, 3) of the constraints they hold (0: dropped), computed
    from the cameras Cn (M, N, 3, 4) (their proven error ``errors`` (M, N(N-1)/2), None: computed here,
    :func:`tritools.model.epipolar_data.fundamental_bounds`)."""
    M = len(v)
    g0, g1, G2 = epipolar_quadratics(F, N)
    good = fin & np.isfinite(g0).all(axis=1) & np.isfinite(g1).all(axis=(1, 2))
    n = 2 * N
    radius = np.sqrt(np.einsum("mi,mi->m", v, v))
    ver = verify_quadratic_batch(np.zeros(M), np.zeros((M, n)), np.broadcast_to(np.eye(n), (M, n, n)), g0, g1, G2,
                                 v, tolerances=tolerances, radius=radius,
                                 constraint_error=epipolar_errors(F, view_pairs(N), v, radius, Cn, errors))
    with np.errstate(invalid="ignore", over="ignore"):
        lb = np.maximum(np.minimum(ver.lower_bound, radius ** 2), 0.0) / (s * s) * ROUND_DOWN
        good &= np.isfinite(lb)
        lb = np.where(good, lb, 0.0)
        if not accepted:
            return lb, None
        ub = radius ** 2 / (s * s)
        return lb, good & np.asarray(tolerances.certified(lb, ub, ub / size), bool)


def ascended_bound(Cn, F, defined, W: np.ndarray, Xn: np.ndarray, s: float, tolerances, need: float,
                   errors=None) -> float:
    """The L2 lower bound (pixels^2) of one subset ``W`` (N,) of one problem (Cn (N, 3, 4), F (K, 3, 3), ``defined``
    (K,) and F's proven errors ``errors`` (K,; None: computed) of :func:`fundamentals`, frame scale ``s``) by the
    best degree-2 certificate rather than the one at the candidate Xn (3,) (:func:`sospoly.analysis.ascend_one`
    from the candidate's KKT multipliers, stopping once the bound passes ``need`` pixels^2; the bound itself
    :func:`sospoly.analysis.bound_at_one` at the multipliers found, with the rigorous margin on the ball of the
    candidate's norm, rounded as :func:`_verified` rounds).  0 when
    no bound is found.  Where the relaxation is not tight at the candidate (a wrong match among three views: the
    KKT multipliers' Lagrangian is indefinite) its SDP value may still exceed what a search needs."""
    N = len(W)
    u, _, fin = project_stack(Cn[None], Xn[None])
    if not (fin[0] and np.isfinite(Xn).all()):
        return 0.0
    v = np.where(W[:, None], u[0], 0.0).reshape(-1)
    I, J = view_pairs(N)
    held = W[I] & W[J] & defined
    g0, g1, G2 = epipolar_quadratics(np.where(held[:, None, None], F, 0.0)[None], N)
    if not (np.isfinite(g0).all() and np.isfinite(g1).all()):
        return 0.0
    n = 2 * N
    radius = float(np.sqrt(v @ v))
    err = epipolar_errors(np.where(held[:, None, None], F, 0.0)[None], (I, J), v[None], radius, Cn[None],
                          None if errors is None else errors[None])
    ver = verify_quadratic_batch(np.zeros(1), np.zeros((1, n)), np.eye(n)[None], g0, g1, G2, v[None],
                                 tolerances=tolerances, radius=np.array([radius]), constraint_error=err)
    found = ascend_one(0.0, np.zeros(n), np.eye(n), g0[0], g1[0], G2, ver.multipliers[0],
                       target=need * s * s * (1.0 + ASCENT_HEADROOM))
    if found is None:
        return 0.0
    out = bound_at_one(0.0, np.zeros(n), np.eye(n), g0[0], g1[0], G2, found[0], radius * radius, tolerances, radius,
                       err[0])
    with np.errstate(invalid="ignore", over="ignore"):
        lb = max(min(float(out.lower_bound[0]), radius * radius), 0.0) / (s * s) * ROUND_DOWN
    return lb if np.isfinite(lb) else 0.0


#: :func:`ascended_bound` climbs past the need by this fraction (the rigorous margin then takes a little)
ASCENT_HEADROOM = 1e-6


def _subset_bounds(Cn, F, defined, Xn: np.ndarray, s: np.ndarray, tolerances, accepted=True, errors=None):
    """:func:`enum_bounds_rows` of rows holding all their k views: cameras Cn (M, k, 3, 4), F (M, k(k-1)/2, 3, 3),
    ``defined`` and F's proven ``errors`` (None: computed) of the pairs of :func:`view_pairs` (k)."""
    M, N = Cn.shape[:2]
    u, _, fin = project_stack(Cn, Xn)
    fin &= np.isfinite(Xn).all(axis=1)
    v = np.where(fin[:, None, None], u, 0.0).reshape(M, -1)
    return _verified(v, fin, np.where(defined[..., None, None], F, 0.0), N, s, tolerances, N, accepted, Cn, errors)


@functools.lru_cache(maxsize=16)
def subset_of(N: int) -> np.ndarray:
    """(M, M) bool: row m's set is a subset of row f's (rows of :func:`subset_masks`; read-only)."""
    bits = subset_masks(N).astype(np.int64) @ (1 << np.arange(N))
    out = (bits[:, None] & ~bits[None, :]) == 0
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=16)
def row_of(N: int) -> np.ndarray:
    """The row of :func:`subset_masks` of each subset by bit mask (-1 for |S| <= 1; read-only)."""
    out = np.full(1 << N, -1)
    out[subset_masks(N).astype(np.int64) @ (1 << np.arange(N))] = np.arange(len(subset_masks(N)))
    out.flags.writeable = False
    return out


def first_of_runs(sorted_keys: np.ndarray) -> np.ndarray:
    """The index of the first entry of each run of equal keys in a sorted 1-D integer array: ``np.unique``'s
    ``return_index`` for sorted input (its result here), without its per-call overhead."""
    if sorted_keys.size == 0:
        return np.zeros(0, int)
    return np.flatnonzero(np.concatenate(([True], sorted_keys[1:] != sorted_keys[:-1])))
