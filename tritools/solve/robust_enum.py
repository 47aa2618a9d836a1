"""Certified TLS for a few views by subset enumeration: one stacked verification of every inlier set.

For thresholds c_i and point regions (:mod:`tritools.solve.robust`),

    f*_TLS = min over subsets S of [ L2*(S) + c^2(V - S) ],     L2*(S) = min_X sum_{i in S} d_i(X)^2,

with L2*(S) = 0 for |S| <= 1.  For N <= :data:`ENUM_MAX_VIEWS` views there are at most 2^N - N - 1 subsets
with |S| >= 2 (N = 3: 4; N = 5: 26; N = 8: 247), few enough to bound *every* one in one or two stacked calls
(:func:`enumerate_tls`) instead of a branch and bound with several rounds of sub-problems.  Each subset is one
row of a stack of N-view problems in one normalised frame of the whole problem (:func:`enum_frame`: x' = s (x - x_i),
X = X_0 + d X'); a view outside S is masked:

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
data) :func:`enumerate_tls` returns None and the caller runs the branch and bound, which starts from the best
candidate found here.

The decision scale.  ``decision_scale`` needs the L2 normalisation of the whole problem (a Levenberg-Marquardt
run from the DLT point, ~1 ms with a wrong match in the track: more than the rest of this path).  Its value is
never below ``robust.scale_from(SCALE_BOUNDS[1], c^2)`` (the normalisation clips s to SCALE_BOUNDS), and the
certificate rule is monotone in the scale, so where the bounds meet at that floor and do not contradict there,
they meet at the documented scale too: the result is the documented rule's, without the normalisation.  Only
elsewhere is the documented scale computed.
"""
from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import time

import numpy as np

from sospoly.analysis import verify_quadratic_batch

from ..model.cameras import power2_scale
from ..model.exact import dot2
from ..model.normalize import RHO_FLOOR_REL, SCALE_BOUNDS, Normalization
from ..model.stacked import (damped_step, dlt_stack, epipolar_quadratics, fundamental_stack, gauss_newton_polish,
                             next_damping, norms,
                             null_vectors, pixel_scales, project_stack, refine_points_stack, view_pairs)
from .robust_bounds import ROUND_DOWN

__all__ = ["enumerate_tls", "enum_frame", "subset_masks", "closure", "enum_bounds", "ENUM_MAX_VIEWS",
           "POLISH_STEPS", "MASKED_CAMERA", "ENUMERATED"]

#: the enumeration runs for point problems with at most this many views (the branch and bound beyond).  Measured
#: (CVPR 2023 protocol, c = 200 px, 1 px, 12 scenes per cell, median CPU of the search over the enumeration, the two
#: interleaved): with 20% / 40% wrong matches 2.1 / 1.6 at N = 7, 1.5 / 1.3 at N = 8, 1.2 / 0.8 at N = 9 (0.4 / 0.3
#: at N = 10 before the two-stack candidates); clean tracks 0.8-0.9 at N = 7-9 (the search's root certificate).
ENUM_MAX_VIEWS = 8
#: Levenberg-Marquardt steps polishing each row's DLT start.
POLISH_STEPS = 5
#: a masked view's camera: Phi(X, P) = (0, 0) for every X (module docstring).
MASKED_CAMERA = np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
#: the result's message says this when the enumeration decided it.
ENUMERATED = "every inlier set enumerated"
#: :func:`_polish` stops when no row's cost changes by more than this fraction in a step.
POLISH_RTOL = 1e-13


@functools.lru_cache(maxsize=16)
def subset_masks(N: int) -> np.ndarray:
    """Every subset of the N views with at least 2 views, as rows of an (M, N) bool array, by size then
    lexicographically (read-only)."""
    rows = [np.isin(np.arange(N), S) for k in range(2, N + 1) for S in itertools.combinations(range(N), k)]
    out = np.array(rows, bool).reshape(-1, N)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=16)
def _splits(N: int) -> tuple:
    """Per subset size k >= 2: (the bit masks of the subsets S of size k, (S, T, S - T) bit masks of every split
    of such S into two non-empty parts with T the part holding S's lowest view)."""
    out = []
    for k in range(2, N + 1):
        S_all, rows = [], []
        for S in itertools.combinations(range(N), k):
            bits = sum(1 << i for i in S)
            S_all.append(bits)
            rest = S[1:]
            for r in range(0, len(rest)):
                for extra in itertools.combinations(rest, r):
                    T = (1 << S[0]) | sum(1 << i for i in extra)
                    rows.append((bits, T, bits ^ T))
        out.append((np.array(S_all), np.array(rows).reshape(-1, 3)))
    return tuple(out)


def closure(N: int, lb_by_bits: np.ndarray) -> np.ndarray:
    """The superadditive closure of subset bounds indexed by bit mask (2^N,; entries of |S| <= 1 are 0):
    L(S) = max(L(S), max over splits S = T + R of (L(T) + L(R)) rounded down), by increasing size, so the parts
    are closed first.  Valid: L2*(S) >= L2*(T) + L2*(R) for disjoint T, R (each term of the sum over S is a term
    of one part, each part's L2* is a minimum over X)."""
    L = lb_by_bits.copy()
    for subsets, sp in _splits(N):
        best = np.zeros(len(L))
        np.maximum.at(best, sp[:, 0], (L[sp[:, 1]] + L[sp[:, 2]]) * ROUND_DOWN)
        L[subsets] = np.maximum(L[subsets], best[subsets])
    return L


def enum_frame(C: np.ndarray, x: np.ndarray):
    """A normalisation of the whole point problem (cameras C (N, 3, 4), points x (N, 2)) without the local
    refinement of :func:`tritools.model.normalize.normalization_for`: X_0 the DLT point (solved in a world translated
to the mean camera centre), d the median distance
    to the camera centres, s = 1 / rho with rho the RMS residual of X_0 (floored at ``RHO_FLOOR_REL`` times the
    median pixel scale, s clipped to ``SCALE_BOUNDS``).  Any frame gives exact identities (module docstring);
    this one only conditions the numbers.  None where it cannot be formed (the caller runs the search, whose
    normalisation handles degenerate data)."""
    C = C / power2_scale(C, (1, 2))                        # exact: a georeferenced centre stays where it is
    a = null_vectors(C)
    if np.any(np.abs(a[:, 3]) <= 1e-12 * norms(a, axis=1)):
        return None                                        # a centre at infinity
    centres = a[:, :3] / a[:, 3:]
    c0 = np.mean(centres, axis=0)                          # the DLT in a world centred on the cameras: georeferenced
    Cc = C.copy()                                          # coordinates (1e6 m) would drown its linear system;
    Cc[..., 3] = dot2(C[..., :3], np.broadcast_to(c0, (len(C), 3, 3)), C[..., 3])   # exact up to one rounding
    X0, ok = dlt_stack(Cc[None], x[None])
    if not ok[0] or not np.all(np.isfinite(X0)):
        return None
    X0 = X0[0]
    u, _, fin = project_stack(Cc[None], X0[None])
    d = float(np.median(norms(centres - c0 - X0, axis=1)))
    if not fin[0]:
        return None
    rho = math.sqrt(float(np.sum((u[0] - x) ** 2)) / len(x))
    # the floor (zero noise): pixel scales are at most ||P[:2, :3] - x P[2, :3]||_F / ||P[2, :3]||, computed only
    # where that bound does not already put the floor below rho
    B = C[:, :2, :3] - x[:, :, None] * C[:, 2:3, :3]
    with np.errstate(divide="ignore", invalid="ignore"):
        top = norms(B, axis=(1, 2)) / norms(C[:, 2, :3], axis=1)
    if not rho > RHO_FLOOR_REL * float(np.max(top)):
        ps = pixel_scales(C[None], x[None])[0]
        ps = ps[np.isfinite(ps) & (ps > 0)]
        rho = max(rho, RHO_FLOOR_REL * float(np.median(ps)) if ps.size else 0.0)
    if not (math.isfinite(d) and d > 0 and math.isfinite(rho) and rho > 0):
        return None
    s = min(max(1.0 / rho, SCALE_BOUNDS[0]), SCALE_BOUNDS[1])
    norm = Normalization(s, x, c0 + X0, d)
    # P'_i = T_i P_i H / ||.||_F (Normalization.cameras, vectorised): T_i = [[s, 0, -s x_i], [0, s, -s y_i], [0, 0, 1]]
    CH = np.concatenate([C[..., :3] * d, (Cc @ np.append(X0, 1.0))[..., None]], axis=2)
    Cn = CH.copy()
    Cn[:, :2] = s * (CH[:, :2] - x[..., None] * CH[:, 2:3])
    Cn /= norms(Cn, axis=(1, 2))[:, None, None]
    return (norm, Cn) if np.all(np.isfinite(Cn)) else None


def _polish(Cm: np.ndarray, X: np.ndarray, steps: int) -> np.ndarray:
    """At most ``steps`` Levenberg-Marquardt steps on sum_i ||Phi(X, P_i)||^2 for a stack of masked cameras
    Cm (M, N, 3, 4) (observations at the origin), a step kept where it does not raise the cost; stops once no
    row's cost moves by POLISH_RTOL of it.  Any candidate gives a valid bound: this only tightens it."""
    mu = np.full(len(X), 1e-3)
    with np.errstate(all="ignore"):
        u, h, fin = project_stack(Cm, X)
        cost = np.where(fin, np.sum(u * u, axis=(1, 2)), np.inf)
        for _ in range(steps):
            den = np.where(h[..., 2] == 0, 1.0, h[..., 2])
            J = ((Cm[..., :2, :3] - u[..., None] * Cm[..., 2:3, :3]) / den[..., None, None]).reshape(len(X), -1, 3)
            r = u.reshape(len(X), -1)
            step = damped_step(np.einsum("mki,mkj->mij", J, J), np.einsum("mki,mk->mi", J, r), mu)
            Xt = X + np.where(np.isfinite(step), step, 0.0)
            ut, ht, fint = project_stack(Cm, Xt)
            ct = np.where(fint, np.sum(ut * ut, axis=(1, 2)), np.inf)
            better = ct <= cost
            settled = np.all(np.isfinite(cost) & (np.abs(ct - cost) <= POLISH_RTOL * cost))
            X = np.where(better[:, None], Xt, X)
            if settled:
                break
            u, h = np.where(better[:, None, None], ut, u), np.where(better[:, None, None], ht, h)
            cost = np.where(better, ct, cost)
            mu = next_damping(mu, better)
    return X


def enum_candidates(Cn: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Normalised candidates Xn (M, 3) (NaN where not finite) of the subsets ``W`` (M, N) of the views of the
    normalised cameras Cn (N, 3, 4): the DLT of each subset polished by :data:`POLISH_STEPS` Levenberg-Marquardt
    steps, all in one masked stack (module docstring)."""
    M, N = W.shape
    Cm = np.where(W[:, :, None, None], Cn[None], MASKED_CAMERA)
    X0, ok = dlt_stack(Cm, np.zeros((M, N, 2)))
    Xn = _polish(Cm, np.where(ok[:, None] & np.isfinite(X0), X0, 0.0), POLISH_STEPS)
    return np.where(np.isfinite(Xn).all(axis=1)[:, None], Xn, np.nan)


def enum_bounds(C: np.ndarray, Cn: np.ndarray, W: np.ndarray, Xn: np.ndarray, s: float, tolerances):
    """(L2 lower bounds (M,) pixels^2, accepted (M,)) of the subsets ``W`` (M, N) at the normalised candidates Xn
    (M, 3), frame scale s (module docstring): the Lagrangian bound of the degree-2 program of each subset, the
    epipolar constraints of its view pairs only.  The fundamental matrices are those of the N views, computed
    once.  ``accepted``: the bound meets the candidate's value under the certificate rule at the subset's
    residual scale (as :func:`tritools.solve.robust_verify.verify_in_parent` accepts a bound)."""
    M, N = W.shape
    u, _, fin = project_stack(np.broadcast_to(Cn, (M,) + Cn.shape), Xn)
    fin &= np.isfinite(Xn).all(axis=1)
    v = np.where(W[:, :, None] & fin[:, None, None], u, 0.0).reshape(M, -1)
    Cs = C / norms(C, axis=(1, 2))[:, None, None]
    F, defined = fundamental_stack(np.stack([Cn, Cs]))       # coincident centres decided on the raw cameras too
    I, J = view_pairs(N)
    held = W[:, I] & W[:, J] & (defined[0] & defined[1])[None]
    g0, g1, G2 = epipolar_quadratics(np.where(held[..., None, None], F[0][None], 0.0), N)
    good = fin & np.isfinite(g0).all(axis=1) & np.isfinite(g1).all(axis=(1, 2))
    n = 2 * N
    radius = np.sqrt(np.einsum("mi,mi->m", v, v))
    ver = verify_quadratic_batch(np.zeros(M), np.zeros((M, n)), np.broadcast_to(np.eye(n), (M, n, n)), g0, g1, G2,
                                 v, tolerances=tolerances, radius=radius)
    with np.errstate(invalid="ignore", over="ignore"):
        lb = np.maximum(np.minimum(ver.lower_bound, radius ** 2), 0.0) / (s * s) * ROUND_DOWN
        good &= np.isfinite(lb)
        lb = np.where(good, lb, 0.0)
        ub = radius ** 2 / (s * s)
        accepted = good & np.asarray(tolerances.certified(lb, ub, ub / W.sum(axis=1)), bool)
    return lb, accepted


def _refined(search, norm, Cn: np.ndarray, X: np.ndarray) -> tuple:
    """(S, the candidate X refined to convergence on its inlier set S, normalised) by
    :func:`tritools.model.stacked.refine_points_stack` in the frame (a row's few polish steps leave the L2
    optimum of a set short by ~1e-6 in X, though not in f); (S, None) where S has < 2 views or it fails."""
    S = sorted(search.inlier_set(X))
    if len(S) < 2:
        return S, None
    zeros = np.zeros((1, len(S), 2))
    Xn, ok = refine_points_stack(Cn[S][None], zeros, norm.normalized_point(X)[None], np.ones(1, bool))
    Xn = gauss_newton_polish(Cn[S][None], zeros, Xn, ok)     # a weak direction the damped LM left (tiny baselines)
    return S, (Xn[0] if ok[0] and np.all(np.isfinite(Xn[0])) else None)


def _offer_rows(search, norm, Cn: np.ndarray, Xn: np.ndarray) -> None:
    """Offer the best row candidate (world frame) to the search, refined (:func:`_refined`: its f_TLS is at most
    the candidate's, whose inlier set it minimises over), and put the refined point in the row of its inlier set
    (whose bound is then taken at the L2 optimum); the candidate itself where the refinement fails."""
    rows = np.nonzero(np.isfinite(Xn).all(axis=1))[0]
    if not rows.size:
        return
    k = rows[int(np.argmin(search.screen(norm.origin + norm.depth * Xn[rows])))]
    S, Xr = _refined(search, norm, Cn, norm.world_point(Xn[k]))
    if Xr is None:
        search.offer(norm.world_point(Xn[k]))
        return
    search.offer(norm.world_point(Xr))
    Xn[_row_of(len(Cn))[sum(1 << i for i in S)]] = Xr


@functools.lru_cache(maxsize=16)
def _row_of(N: int) -> np.ndarray:
    """The row of :func:`subset_masks` of each subset by bit mask (-1 for |S| <= 1; read-only)."""
    out = np.full(1 << N, -1)
    out[subset_masks(N).astype(np.int64) @ (1 << np.arange(N))] = np.arange(len(subset_masks(N)))
    out.flags.writeable = False
    return out


def enumerate_tls(search):
    """The TLS result of a :class:`tritools.solve.robust.TlsSearch` of a point problem with 3 to
    :data:`ENUM_MAX_VIEWS` views by enumeration (module docstring), or None (the caller runs the search, which has
    been offered the best candidates found here).

    Steps: the candidates of the view pairs and of all views (one masked stack) give a first UB; the subsets whose
    c^2(V - S) alone does not meet it get their candidates (a second stack), which may lower UB; then the
    subsets whose c^2(V - S) does not meet UB get their Lagrangian bound in one stacked call, with the view pairs
    when the best candidate has an outlier (their bounds feed the closure of the sets holding it); the others keep
    the bound 0 (their term c^2(V - S) meets UB already).  Where LB does not meet UB then, every other subset gets
    its candidate and bound too (a second stacked call) before the closure is taken again.  The deadline is
    checked between the stacks: once it has passed, None (the search then reports the time limit, with the
    candidates offered here and valid bounds)."""
    N = search.N
    if not search.points or not 3 <= N <= ENUM_MAX_VIEWS or search.deadline.expired:
        return None
    try:
        fr = enum_frame(search.C, search.x)
        if fr is None:
            return None
        norm, Cn = fr
        W = subset_masks(N)
        size = W.sum(axis=1)
        Xn = np.full((len(W), 3), np.nan)
        first = (size == 2) | (size == N)
        Xn[first] = enum_candidates(Cn, W[first])
        _offer_rows(search, norm, Cn, Xn)
        if search.best_X is None or search.deadline.expired:     # the search reports its time limit
            return None
        with np.errstate(over="ignore", invalid="ignore"):
            rest = np.sum(np.where(W, 0.0, search.c2[None]), axis=1) * ROUND_DOWN   # c^2(V - S); inf: c_i = inf
        later = _open(search, rest) & ~first
        if later.any():
            Xn[later] = enum_candidates(Cn, W[later])
            _offer_rows(search, norm, Cn, Xn)
            if search.deadline.expired:
                return None
        need = _open(search, rest) | ((size == 2) & (search.best_f > float(np.min(search.c2))))
        lb = np.zeros(len(W))
        if need.any():
            lb[need], _ = enum_bounds(search.C, Cn, W[need], Xn[need], norm.scale, search.tol)
        res = _decide(search, W, lb, rest, int(need.sum()), final=False)
        more = ~need                     # (a set missing a view of infinite c still feeds the closure)
        if res is not None or not more.any() or search.deadline.expired:
            return res if res is not None or search.deadline.expired else _decide(search, W, lb, rest,
                                                                                 int(need.sum()))
        # not met: every other subset too (its own bound feeds the closure of the sets holding it)
        todo = more & ~np.isfinite(Xn).all(axis=1)
        if todo.any():
            Xn[todo] = enum_candidates(Cn, W[todo])
        lb[more], _ = enum_bounds(search.C, Cn, W[more], Xn[more], norm.scale, search.tol)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return None
    return _decide(search, W, lb, rest, len(W))


def _open(search, rest: np.ndarray) -> np.ndarray:
    """The subsets whose term c^2(V - S) alone does not meet UB under the rule at the floor scale (finite only)."""
    from .robust import scale_from

    ub = search.best_f
    met = (rest >= ub) | np.asarray(search.tol.certified(rest, ub, scale_from(SCALE_BOUNDS[1], search.c2)), bool)
    return ~met & np.isfinite(rest)


def _decide(search, W: np.ndarray, lb: np.ndarray, rest: np.ndarray, n_bounded: int, final: bool = True):
    """LB from the closed subset bounds (module docstring) and the result where it meets UB, else None (not
    ``final``: decided at the floor scale only, without the normalisation)."""
    from .robust import scale_from

    N, c2, ub = search.N, search.c2, search.best_f
    bits = W.astype(np.int64) @ (1 << np.arange(N))
    table = np.zeros(1 << N)
    table[bits] = lb
    with np.errstate(over="ignore", invalid="ignore"):
        terms = (closure(N, table)[bits] + rest) * ROUND_DOWN
        small = np.sum(np.where(np.eye(N, dtype=bool), 0.0, c2[None]), axis=1)    # |S| = 1: c^2(V - i) exactly
    lb_all = min(ub, float(np.min(terms)), float(np.min(small)) * ROUND_DOWN, float(np.sum(c2)) * ROUND_DOWN)
    floor = scale_from(SCALE_BOUNDS[1], c2)
    if search.tol.certified(lb_all, ub, floor) and not search.tol.contradicts(lb_all, ub, floor):
        search.set_normalization_scale(SCALE_BOUNDS[1])        # met at the floor: met at the documented scale
    elif not final or not search.tol.certified(lb_all, ub, search.scale):
        return None
    search.bounds.n_solved += n_bounded
    t = time.perf_counter() - search.t0
    res = search.result(lb_all, None, {"enumeration": t, "total": t})
    return dataclasses.replace(res, message=res.message + f"; {ENUMERATED} ({len(W)} sets of >= 2 views)")
