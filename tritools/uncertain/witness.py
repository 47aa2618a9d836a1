"""Witnesses of the per-view set: membership (in floating point), interior candidates, feasible inner points and
the membership check of ray certificates (used by :mod:`.api`)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..model.regions import ConeKind
from .sets import contains

__all__ = ["repeat_block", "take", "feasible", "pull_inside", "centres", "rays_stay_inside", "view_rays", "recedes",
           "exact_rays", "RAY_REACH", "witness_gap"]

#: a ray is accepted when base + lambda d stays in S for lambda = scene scale times these factors
RAY_REACH = (1e-3, 1.0, 1e2)


def repeat_block(blk, K, dtype=float):
    """The block with every problem repeated K times (one per objective), in ``dtype``."""
    rep = {k: (None if v is None else np.repeat(v, K, axis=0).astype(dtype)) for k, v in
           (("center", blk.center), ("D", blk.D), ("Dinv", blk.Dinv), ("L", blk.L), ("B", blk.B), ("c", blk.c),
            ("d", blk.d))}
    return replace(blk, **rep)


def take(blk, idx):
    """The block of the problems ``idx``."""
    return replace(blk, **{k: (None if getattr(blk, k) is None else getattr(blk, k)[idx])
                           for k in ("center", "D", "Dinv", "L", "B", "c", "d")})


def feasible(blocks, R, X, rtol) -> np.ndarray:
    """X (M, 3) in S for problem m (all views)."""
    ok = np.all(np.isfinite(X), axis=1)
    Xs = np.where(ok[:, None], X, 0.0)
    for i, blk in enumerate(blocks):
        tol = rtol if blk.kind in ("point", "segment") else 0.0
        ok &= contains(blk, R[:, i], Xs, tol)
    return ok


def pull_inside(blocks, R, W, centre, rtol) -> np.ndarray:
    """Witnesses W (M, K, 3) moved the least step of a ladder towards ``centre`` (M, 3) that makes
    them feasible; NaN where none does."""
    M, K, _ = W.shape
    out = np.full(W.shape, np.nan)
    todo = np.all(np.isfinite(W), axis=2)
    Rk = np.repeat(R, K, axis=0)
    blk_rep = [repeat_block(b, K) for b in blocks]
    C = np.repeat(centre, K, axis=0).reshape(M, K, 3)
    for theta in (0.0, 1e-12, 1e-10, 1e-8, 1e-6, 1e-4, 1e-3, 1e-2, 0.1, 0.5, 1.0):
        cand = W + theta * (C - W)
        ok = feasible(blk_rep, Rk, cand.reshape(M * K, 3), rtol).reshape(M, K) & todo
        out[ok] = cand[ok]
        todo &= ~ok
        if not np.any(todo):
            break
    return out


def centres(blocks, R, W, X0, dirs, sigma, rtol):
    """An interior candidate per problem: the first feasible of the mean of its finite witnesses, X0,
    and both moved along the mean ray direction (unbounded sets: into the recession cone) by
    1..1e4 sigma; X0 where none is."""
    fin = np.isfinite(W)
    cnt = fin.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(fin, W, 0.0).sum(axis=1) / cnt
        dbar = np.where(np.isfinite(dirs), dirs, 0.0).sum(axis=1)
        dbar = dbar / np.linalg.norm(dbar, axis=1, keepdims=True)
    mean = np.where(np.isfinite(mean), mean, X0)
    dbar = np.where(np.isfinite(dbar), dbar, 0.0)
    out = X0.copy()
    todo = np.ones(len(X0), bool)
    cands = [mean, X0] + [p + (t * sigma)[:, None] * dbar for t in (1.0, 10.0, 1e2, 1e3, 1e4) for p in (mean, X0)]
    for c in cands:
        ok = todo & feasible(blocks, R, c, rtol)
        out[ok] = c[ok]
        todo &= ~ok
        if not np.any(todo):
            break
    return out


def view_rays(blocks, R, m: int) -> list:
    """The unit centre rays d_i of problem m's views, R_i[:, :3] d_i = (x^_i, 1) (depth s = 1 > 0 along them; a view
    that is singular there is skipped).  A tiny region (a point widened by its round-off) has no other recession
    direction: a solver's float ray leaves it, its own centre ray stays in it up to rounding (review 39a F4: a point
    and a 3 px disc seen by cameras 0.01 apart, an unbounded set, was reported ``failed``)."""
    out = []
    for i, blk in enumerate(blocks):
        try:
            d = np.linalg.solve(R[m, i, :, :3], np.append(blk.center[m], 1.0))
        except np.linalg.LinAlgError:
            continue
        n = float(np.linalg.norm(d))
        if np.all(np.isfinite(d)) and n > 0:
            out.append(d / n)
    return out


#: distances along each view's centre ray, as multiples of the scene's size, where an "empty" verdict looks for a point
RAY_PROBES = tuple(10.0 ** (k / 2) for k in range(-6, 35))


def ray_point_in_set(blocks, R, size, rtol, rows) -> np.ndarray:
    """(M,) bool: for the problems ``rows`` (a mask), a point of S on some view's centre ray (from its camera centre,
    :func:`view_rays`, at ``RAY_PROBES`` times ``size``) or at two such rays' closest points.  A Farkas verdict
    excludes a ball only; the sets it missed were the points of nearly parallel rays, far along them (review 45b H1:
    0.2 px discs of a stereo pair with zero disparity, S the optical axis beyond depth 2000, called empty)."""
    found = np.zeros(len(rows), bool)
    idx = np.flatnonzero(rows)
    if not idx.size:
        return found
    Rm = R[idx]                                                     # (E, N, 3, 4)
    E, N = Rm.shape[:2]
    w = np.linalg.svd(Rm.reshape(-1, 3, 4))[2][:, -1].reshape(E, N, 4)
    centre = np.stack([np.append(b.center[idx][e], 1.0) for e in range(E) for b in blocks]).reshape(E, N, 3)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        C = w[..., :3] / w[..., 3:]
        d = _solve3(Rm[..., :3], centre)
        d = d / np.linalg.norm(d, axis=2, keepdims=True)
        t = np.asarray(RAY_PROBES)[None, None, :, None] * size[idx][:, None, None, None]
        along = (C[:, :, None, :] + t * d[:, :, None, :]).reshape(E, -1, 3)
        cand = np.concatenate([along, _closest(C, d)], axis=1)      # (E, Kc, 3)
    Kc = cand.shape[1]
    ok = np.all(np.isfinite(cand), axis=2)
    rep = [repeat_block(take(b, idx), Kc) for b in blocks]
    inside = feasible(rep, np.repeat(Rm, Kc, axis=0), np.where(ok[..., None], cand, 0.0).reshape(-1, 3), rtol)
    found[idx] = np.any(inside.reshape(E, Kc) & ok, axis=1)
    return found


def _solve3(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x with A x = y for stacks of 3 x 3 systems by Cramer's rule (NaN where A is singular)."""
    det = np.linalg.det(A)
    out = np.empty(y.shape)
    for k in range(3):
        Ak = A.copy()
        Ak[..., :, k] = y
        out[..., k] = np.linalg.det(Ak) / det
    return np.where(np.isfinite(out), out, np.nan)


def _closest(C: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(E, N (N - 1), 3): for every ordered pair of rays (C_a + t d_a), the point of ray a closest to ray b (cross
    products: accurate for nearly parallel rays, where the DLT of the centres fails as 'at infinity'); NaN where it
    is behind C_a or undefined."""
    E, N = C.shape[:2]
    a, b = np.array([(i, j) for i in range(N) for j in range(N) if i != j]).T
    n = np.cross(d[:, a], d[:, b])
    nn = np.einsum("eka,eka->ek", n, n)
    t = np.einsum("eka,eka->ek", np.cross(C[:, b] - C[:, a], d[:, b]), n) / nn
    t = np.where(np.isfinite(t) & (t > 0), t, np.nan)
    return C[:, a] + t[..., None] * d[:, a]


def _snapped(blocks, R, eta, targets) -> list:
    """Per ray, the view rays (:func:`view_rays`) on the side of the solver's ray ``eta`` that decrease ``targets``."""
    out = []
    for m in range(len(eta)):
        t = targets[m]
        out.append([d for d in view_rays(blocks, R, m) if float(d @ eta[m]) > 0 and _descends(t, d)])
    return out


def _descends(t: np.ndarray, c: np.ndarray) -> bool:
    """Does the finite direction c decrease the objective t clear of rounding (t . c < -1e-12 |t| |c|)?"""
    return bool(np.all(np.isfinite(c))) and float(t @ c) < -1e-12 * float(np.linalg.norm(t) * np.linalg.norm(c))


def rays_stay_inside(blocks, R, W, centre, eta, ray, rtol, targets) -> np.ndarray:
    """(M, K) False where a ray certificate fails the (float) membership test: from a feasible base point
    (the interior candidate, else a feasible witness) the points ``base + lambda d`` must lie in S for
    lambda up to 1e2 times the scene's scale (distance to the farthest camera centre).  A recession
    direction of S passes; a direction that only nearly satisfies a thin cone (a widened point) leaves
    it and is refused (the side is then not reported infinite: the problem is reported failed)."""
    M, K, _ = W.shape
    keep = np.ones((M, K), bool)
    pm, ko = np.nonzero(ray)
    if len(pm) == 0:
        return keep
    base = centre.copy()
    ok = feasible(blocks, R, base, rtol)
    for k in range(K):                                  # a feasible witness where the centre is not
        use = ~ok & np.all(np.isfinite(W[:, k]), axis=1)
        base[use], ok[use] = W[use, k], True
    w = np.linalg.svd(R.reshape(-1, 3, 4))[2][:, -1].reshape(M, -1, 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.nanmax(np.linalg.norm(w[..., :3] / w[..., 3:] - base[:, None], axis=2), axis=1)
    d = eta[pm, ko] / np.linalg.norm(eta[pm, ko], axis=1, keepdims=True)
    good = ok[pm] & np.all(np.isfinite(d), axis=1) & np.isfinite(scale[pm])
    sub = [take(b, pm) for b in blocks]
    for lam in RAY_REACH:
        good &= feasible(sub, R[pm], base[pm] + (lam * scale[pm])[:, None] * d, rtol)
    if _exact_kinds(blocks) and not good.all():         # a view's own ray (view_rays, decreasing ``targets``); only
        # where exact_rays then decides the ray exactly (a segment's float test alone could pass a direction
        # that is bounded far away)
        for r, cands in enumerate(_snapped(sub, R[pm], d, targets[pm, ko])):
            if good[r] or not (ok[pm[r]] and np.isfinite(scale[pm[r]])):
                continue
            one = [take(b, [r]) for b in sub]
            good[r] = any(all(bool(feasible(one, R[pm][[r]], base[pm][[r]] + lam * scale[pm[r]] * c[None], rtol)[0])
                              for lam in RAY_REACH) for c in cands)
    keep[pm, ko] = good
    return keep


def recedes(blocks, R, d) -> np.ndarray:
    """(M,) whether (d, 0) is a recession direction of S, decided in exact rational arithmetic on the float data
    (cameras R (M, N, 3, 4), directions d (M, 3)), for problems whose views are all ellipses or polytopes; True for
    the others (points and segments have no interior, no float direction meets their equalities exactly: their
    rays keep the float test of :func:`rays_stay_inside`).  Each view's set is a convex cone K_i in X~ = (X, 1),
    (a, s) = (r_1 X~, r_2 X~, r_3 X~); when (a_d, s_d) = R_i (d, 0) is in K_i, (a, s) + lambda (a_d, s_d) stays in
    K_i for every lambda >= 0, so S holds base + lambda d for every base in S: a ray.  A direction that only
    nearly meets a cone (a set bounded at a depth of 1e10 seen by parallel cameras, review 26b F2) is refused."""
    from fractions import Fraction

    M = len(d)
    out = np.ones(M, bool)
    if not _exact_kinds(blocks):
        return out
    for m in range(M):
        if not all(math.isfinite(float(v)) for v in d[m]):      # (a NaN has no Fraction)
            out[m] = False
            continue
        dm = [Fraction(float(v)) for v in d[m]]
        for i, blk in enumerate(blocks):
            a0, a1, s_ = (sum(Fraction(float(R[m, i, r, k])) * dm[k] for k in range(3)) for r in range(3))
            if s_ < 0 or not _in_cone(blk, m, a0, a1, s_):
                out[m] = False
                break
    return out


def exact_rays(blocks, R, eta, ray, targets) -> np.ndarray:
    """(M, K) the rays of ``ray`` that keep their claim: a direction that recedes exactly (:func:`recedes`) and
    decreases the objective ``targets`` (M, K, 3), tried from the ray's own direction eta (M, K, 3), the mean of the
    problem's ray directions, the mean of the views' centre rays (R_i d = (x^_i, 1): inside overlapping regions),
    each view's own (:func:`view_rays`: a point widened by its round-off) and their midpoints with eta -- a
    solver's ray lies on the recession cone's boundary, where a float direction falls on either side of it (two
    parallel cameras with overlapping discs, review 26c F4).  Where a view is a point or a segment (kept as such by
    ``widen_roundoff=False``) no ray is decided exactly, so none is kept: that side is failed, not unbounded."""
    out = ray.copy()
    pm, ko = np.nonzero(ray)
    if not pm.size:
        return out
    if not _exact_kinds(blocks):        # a point or segment view (widen_roundoff=False): no exact decision, no ray
        out[pm, ko] = False             # claimed -- the float test alone passed sets bounded at 8e11 (review 45b M2)
        return out
    with np.errstate(all="ignore"):
        unit = eta / np.linalg.norm(eta, axis=2, keepdims=True)
    for m in np.unique(pm):
        ks = ko[pm == m]
        sub, Rm = [take(b, [m]) for b in blocks], R[[m]]
        rays = view_rays(blocks, R, m)
        centre = np.mean(rays, axis=0) if len(rays) == len(blocks) else np.full(3, np.nan)   # (the views' mean)
        common = [np.nanmean(unit[m, ks], axis=0), centre] + rays
        for k in ks:
            cands = [eta[m, k]] + common + [0.5 * (unit[m, k] + c) for c in common]
            t = targets[m, k]
            out[m, k] = any(_descends(t, c) and bool(recedes(sub, Rm, np.asarray(c, float)[None])[0]) for c in cands)
    return out


def _exact_kinds(blocks) -> bool:
    """Every view an ellipse or a polytope: the views whose cones :func:`recedes` decides exactly."""
    return all(b.kind in (ConeKind.ELLIPSE, ConeKind.POLYTOPE) for b in blocks)


def _in_cone(blk, m: int, a0, a1, s_) -> bool:
    """(a, s) in the view's cone (exact): an ellipse v' D^-1 v <= s^2 with v = a - x^ s, through D's adjugate; a
    polytope |B_k a + c_k s| <= s for every row k.  False where the view's data is not finite (a disc of radius
    1e200 has D = inf: no exact decision, so no ray is claimed; review 29b F2)."""
    from fractions import Fraction

    data = (blk.B[m], blk.c[m]) if blk.kind == ConeKind.POLYTOPE else (blk.center[m], blk.D[m])
    if not all(np.all(np.isfinite(np.asarray(a, float))) for a in data):
        return False
    if blk.kind == ConeKind.POLYTOPE:
        return all(abs(Fraction(float(B[0])) * a0 + Fraction(float(B[1])) * a1 + Fraction(float(c)) * s_) <= s_
                   for B, c in zip(blk.B[m], blk.c[m]))
    x0, x1 = (Fraction(float(v)) for v in blk.center[m])
    v0, v1 = a0 - x0 * s_, a1 - x1 * s_
    (d00, d01), (d10, d11) = ([Fraction(float(v)) for v in row] for row in blk.D[m])
    det = d00 * d11 - d01 * d10
    return det > 0 and d11 * v0 * v0 - (d01 + d10) * v0 * v1 + d00 * v1 * v1 <= s_ * s_ * det


def in_box(W, lo, hi) -> np.ndarray:
    """Witnesses W (..., 3) pulled into the certified box [lo, hi]: every point of S lies in the box, so a witness
    outside it is outside S by its projection's round-off and moves by no more than that (review 45b L1: 1 ulp
    below ``lo`` in a world at 3e6, a negative gap); NaN rows stay NaN."""
    return np.clip(np.asarray(W, float), np.asarray(lo, float), np.asarray(hi, float))


def witness_gap(lo, hi, wl, wh, estimate, bounded: bool, points=None):
    """How tight a box [lo, hi] is, from its witnesses (the one rule of :mod:`.api` and :mod:`.level`).

    ``wl[k]`` / ``wh[k]`` (3, 3) are points of the set whose k-th coordinate is near ``lo[k]`` / ``hi[k]`` (NaN
    rows: none found).  Returns (gap, gap_rel, inner, dw): ``gap`` the largest distance of a finite side to its
    witness (inf when a finite side has none; 0 when no side is finite), ``gap_rel`` gap over the box's largest
    width (finite widths only: an unbounded box gives inf unless gap is 0), ``inner`` the largest distance of a
    witness (of ``points``, rows of points of the set; default wl and wh) from ``estimate``, rounded down (a
    lower bound on the set's reach), and ``dw`` that witness."""
    from .rigour import round_down
    from .sets import EPS

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    sides = [wl[k, k] - lo[k] for k in range(3) if np.isfinite(lo[k])] + \
            [hi[k] - wh[k, k] for k in range(3) if np.isfinite(hi[k])]
    gap = float(np.max(sides)) if sides else 0.0
    gap = np.inf if np.isnan(gap) else gap
    width = float(np.max(hi - lo)) if bounded else np.inf
    gap_rel = gap / width if 0 < width < np.inf else (0.0 if gap == 0 else np.inf)
    W = np.vstack([wl, wh]) if points is None else np.asarray(points, float)
    W = W[np.all(np.isfinite(W), axis=1)]
    if not len(W):
        return gap, gap_rel, np.nan, np.full(3, np.nan)
    d = np.linalg.norm(W - estimate, axis=1)
    j = int(np.argmax(d))
    return gap, gap_rel, max(float(round_down(d[j] * (1 - 8 * EPS))), 0.0), W[j].copy()
