"""A lower bound of the TLS optimum by branch and bound over cells of candidate points (point regions).

Why.  The search over inlier sets (:mod:`tritools.solve.robust`) needs, at thresholds of 2-3 sigma on long tracks,
to exclude a combinatorial number of near-optimal inlier sets; here the combinatorics is resolved by geometry.

Patterns.  Order the views (most confident inlier of the best candidate first).  Every X with at least two inliers
(d_i(X) < c_i) has a first inlier a and a second inlier b in that order; every view before b other than a is then
an outlier of X (it pays c^2).  The pattern (a, b) holds those X; the patterns and the X with at most one inlier
(f_TLS >= sum c^2 - max c^2) cover every X, and a pattern whose forced outliers already cost UB is not searched.

Coordinates.  In pattern (a, b), with the images translated so that x_i = 0 (P'_i) and the world so that the best
candidate is the origin, X~ = T_a q with q = (u, v, 1, w):  T_a = [[M_a^{-1}, C_a], [0, 1]] in the columns of
(u, v, 1) and w, M_a = P'_a[:, :3], C_a the centre of view a.  Then the homogeneous image of view i,

    h_i(q) = P'_i T_a q = K_i q,       K_i = P'_i T_a     (affine in (u, v, w): h_a = (u, v, 1)),

so view a's residual is (u, v) (|u|, |v| < c_a), and w (inverse depth along a's ray) is bounded by b's inlier
condition |g_b| < c_b |h_b3|:  |w| (|e_g| - c_b |e_3|) <= max |g_N| + c_b max |h_N3| with e = K_b[:, 3] (the
epipole of a's centre), g_N, h_N the (u, v, 1) part over the square (:func:`w_bound`; unbounded when a's centre
projects within c_b of x_b: the pattern is then refused and the whole bound with it).

Cell bound.  On a box q_c +- r (r = (r_u, r_v, r_w)), per view: h = h_c + J delta, g = (h_1, h_2), the residual
e = g / h_3.  With eta = |J_3| r / |h_3c| < 1 (else the view's bound is 0):
lo = max(0, |g_c| - G) / (|h_3c| (1 + eta)),  hi = (|g_c| + G) / (|h_3c| (1 - eta)),  G = sum_k |J_g,k| r_k;
and the linear model e = e_c + L delta + R,  L = (J_g - e_c J_3) / h_3c,
|R| <= G eta / |h_3c| + (|g_c| + G) eta^2 / (|h_3c| (1 - eta))     (1/(1+t) = 1 - t + t^2/(1+t)).
Views are forced outliers of the pattern (c^2; a cell where one is surely an inlier, hi < c, holds no X of the
pattern), surely outliers (lo >= c: c^2), quadratic (a, b, and surely inliers hi < c: d^2 >= |e_c + L delta|^2 -
2 E R, E = |e_c| + sum_k |L_k| r_k) or ambiguous (min(d, c)^2 >= lo^2).  The quadratic part's minimum over the
box is bounded by the dual of least squares: for every z, |a + L delta|^2 >= 2 z.a - |z|^2 + 2 (L^T z).delta
>= 2 z.a - |z|^2 - 2 sum_k |(L^T z)_k| r_k, taken at z = a + L delta' (delta' a few projected coordinate steps
from the clipped least-squares solution; exact at the box minimiser).  The bound loses only second order in the
cell size where the inlier set is decided, so cells close around a non-degenerate optimum.

Floating point.  The frame is built once in float64; the bound is multiplied by :data:`MARGIN_REL` and the frame
of every reference view is checked on the best candidate (its d_i^2 from K against the direct, compensated
ones, :data:`FRAME_CHECK_REL`): a frame that disagrees is not used (its patterns try the other view, else the bound
is refused).  The reported gamma_LB is lowered further by the report's round-off rule
(:mod:`tritools.solve.robust_report`).

The search is best first, :data:`BATCH` cells split per vectorised step, within :data:`MAX_CELLS` cells and the
caller's deadline; the centres' f_TLS offer candidates to the caller (a better UB prunes more).  The bound
returned is min(UB, min over cells pruned below UB or left open, the one-inlier bound).
"""
from __future__ import annotations

import heapq
import logging
import math
from dataclasses import dataclass

import numpy as np

from ..model.exact import homogeneous_images
from .robust_bounds import NODE_BUDGET_NAME

__all__ = ["search_bound", "cell_lower_bound", "CellBound", "FALLBACK_NODES", "fallback_nodes", "set_node_budget",
           "CELL_BUDGET_NAME", "frame", "w_bound", "evaluate_cells", "MAX_CELLS", "BATCH", "ENABLED", "MIN_VIEWS",
           "MAX_VIEWS"]

log = logging.getLogger(__name__)

#: the cell search is tried (False: the inlier-set search alone; the tests compare the two).
ENABLED = True
#: the cells run from this many views: below it every inlier set is enumerated first (tritools.solve.robust_enum_run,
#: up to 8 views) and the scenes the branch and bound still gets are those whose L2 sub-bounds are weak (trifocal
#: planes), where the cells' box bounds do not close either and cost ~0.35 s each (measured: batches of 3-view
#: tracks at 5 px, 9.9 ms per point with the cells against 1.1 ms without, every point certified either way)
MIN_VIEWS = 9
#: ... and up to this many: the patterns' set-up and their root cells cost ~N^3 before the first deadline check (a
#: 200-view track spent 3 s past a 1 s limit there), and from ~100 views the cell budget runs out anyway
MAX_VIEWS = 100
#: cells evaluated at most per call (a failing search stops there: not_certified, valid bounds).
MAX_CELLS = 60000
#: and at most this many view-cells (cells times views), so that a long track fails in about the same time.
MAX_VIEW_CELLS = 2_400_000
#: after a cell search stopped by its budget, the inlier-set search runs with this node budget (instead of
#: :data:`tritools.solve.robust.MAX_NODES`) on problems of at most :data:`FALLBACK_MAX_VIEWS` views, with none beyond:
#: it closes some small problems the cells miss (the paper's 4-view example at c = 1 px: 15 nodes), while a tight long
#: track it cannot close fails in a second or two, not 8-12 s (N = 100, c = 2 sigma: 300 nodes took 4 s more).
FALLBACK_NODES = 300
FALLBACK_MAX_VIEWS = 12


def fallback_nodes(n_views: int) -> int:
    """The inlier-set search's node budget after an exhausted cell search (:data:`FALLBACK_NODES`)."""
    return FALLBACK_NODES if n_views <= FALLBACK_MAX_VIEWS else 0


#: the stop's name in the message of a search whose cell search used up its budget (review 36a F3: "0 nodes ...
#: stopped by the node budget" named a budget of 0 inlier-set nodes beyond FALLBACK_MAX_VIEWS views).
CELL_BUDGET_NAME = "cell search's budget"


def set_node_budget(search, cells, default: int) -> None:
    """The inlier-set search's node budget after the cell search ``cells`` (None: not run): ``default``, or
    :func:`fallback_nodes` where the cells could not close (the search then closes small cases they miss), named
    :data:`CELL_BUDGET_NAME` with the nodes left after it unless another rule named it (the coplanar ceiling)."""
    exhausted = cells is not None and cells.exhausted
    search.max_nodes = fallback_nodes(search.N) if exhausted else default
    if exhausted and search.bounds.node_budget_name == NODE_BUDGET_NAME:
        n = search.max_nodes
        search.bounds.node_budget_name = CELL_BUDGET_NAME + (f" and the {n} inlier-set nodes after it" if n else
                                                             f" (no inlier-set nodes after it beyond "
                                                             f"{FALLBACK_MAX_VIEWS} views)")


#: cells split per vectorised step.
BATCH = 64
#: every cell bound is multiplied by this (the frame's and the evaluation's round-off, ~1e-13 relative).
MARGIN_REL = 1.0 - 1e-9
#: the frame is refused when the best candidate's sum of d_i^2 from it differs by more than this (relative).
FRAME_CHECK_REL = 1e-9
#: coordinate-descent passes of the box least squares (:func:`_box_ls`).
CD_PASSES = 2


def frame(C: np.ndarray, x: np.ndarray, X0: np.ndarray, a: int):
    """(K (N, 3, 4), T (4, 4)) of reference view a (module docstring): h_i = K_i (u, v, 1, w) in images translated to
    x_i = 0, and X~ - (X0, 0) w = T (u, v, 1, w) in the world translated to X0.  None if M_a is singular."""
    Pt = C.copy()
    Pt[:, :, 3] = homogeneous_images(C, np.append(X0, 1.0))  # world translated to X0 (compensated: georeferenced)
    Pt[:, :2, :] -= x[:, :, None] * Pt[:, 2:3, :]           # P'_i: image translated to x_i = 0
    M = Pt[a, :, :3]
    try:
        Minv = np.linalg.inv(M)
        centre = -np.linalg.solve(M, Pt[a, :, 3])
    except np.linalg.LinAlgError:
        return None
    if not (np.all(np.isfinite(Minv)) and np.all(np.isfinite(centre))):
        return None
    T = np.zeros((4, 4))
    T[:3, :3] = Minv
    T[:3, 3] = centre
    T[3, 3] = 1.0
    return Pt @ T, T


def w_bound(Kb: np.ndarray, cb: float, ca: float) -> float:
    """W with |w| <= W for every q of the square |u|, |v| <= ca at which view b is an inlier (module docstring);
    inf where a's centre projects within cb of x_b."""
    e = Kb[:, 3]
    den = math.hypot(e[0], e[1]) - cb * abs(e[2])
    g0 = math.hypot(Kb[0, 2], Kb[1, 2]) + ca * (math.hypot(Kb[0, 0], Kb[1, 0]) + math.hypot(Kb[0, 1], Kb[1, 1]))
    h0 = abs(Kb[2, 2]) + ca * (abs(Kb[2, 0]) + abs(Kb[2, 1]))
    if not den > 1e-9 * (math.hypot(e[0], e[1]) + cb * abs(e[2])):
        return math.inf
    return (g0 + cb * h0) / den * (1 + 1e-9)


def _box_ls(a: np.ndarray, L: np.ndarray, m: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Lower bounds (B,) of min over |delta_k| <= r_k of sum_{i: m} |a_i + L_i delta|^2 (a (B, N, 2), L (B, N, 2, 3),
    mask m (B, N)): the least-squares dual at z = a + L delta' (module docstring)."""
    w = m[..., None, None]
    Lm = np.where(w, L, 0.0)
    am = np.where(m[..., None], a, 0.0)
    A = np.einsum("bnjk,bnjl->bkl", Lm, Lm)
    g = np.einsum("bnjk,bnj->bk", Lm, am)
    reg = 1e-12 * (np.trace(A, axis1=1, axis2=2) + 1e-300)
    with np.errstate(all="ignore"):
        try:                                             # any delta gives a valid bound: this one is near the best
            d = -np.linalg.solve(A + reg[:, None, None] * np.eye(3), g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            d = np.zeros_like(g)
        d = np.where(np.isfinite(d), d, 0.0)
        d = np.clip(d, -r, r)
        diag = np.einsum("bkk->bk", A)
        for _ in range(CD_PASSES):
            for k in range(3):
                step = (np.einsum("bl,bl->b", A[:, k], d) + g[:, k]) / np.where(diag[:, k] > 0, diag[:, k], np.inf)
                d[:, k] = np.clip(d[:, k] - step, -r[:, k], r[:, k])
    z = am + np.einsum("bnjk,bk->bnj", Lm, d)
    Ltz = np.einsum("bnjk,bnj->bk", Lm, z)
    return np.sum(2 * z * am - z * z, axis=(1, 2)) - 2 * np.sum(np.abs(Ltz) * r, axis=1)


def evaluate_cells(K: np.ndarray, c2: np.ndarray, forced: np.ndarray, need: np.ndarray, qc: np.ndarray,
                   r: np.ndarray):
    """(bound (B,), f_TLS at the centres (B,), split direction (B,)) of cells q_c +- r (B, 3) = (u, v, w), each with
    its frame K (B, N, 3, 4), forced outliers and required inliers (B, N) (module docstring)."""
    J = K[..., [0, 1, 3]]                                                # (B, N, 3, 3)
    hc = K[..., 2] + np.einsum("bnjk,bk->bnj", J, qc)                   # (B, N, 3)
    absJ3 = np.abs(J[:, :, 2, :])
    R3 = np.einsum("bnk,bk->bn", absJ3, r)
    h3 = hc[..., 2]
    ah3 = np.abs(h3)
    with np.errstate(all="ignore"):
        eta = R3 / ah3
        valid = eta < 0.5
        colg = np.sqrt(J[:, :, 0, :] ** 2 + J[:, :, 1, :] ** 2)          # (B, N, 3)
        G = np.einsum("bnk,bk->bn", colg, r)
        gn = np.hypot(hc[..., 0], hc[..., 1])
        lo = np.where(valid, np.maximum(0.0, gn - G) / (ah3 * (1 + eta)), 0.0)
        hi = np.where(valid, (gn + G) / (ah3 * (1 - eta)), np.inf)
        ec = np.where(valid[..., None], hc[..., :2] / h3[..., None], 0.0)
        L = (J[:, :, :2, :] - ec[..., None] * J[:, :, 2:3, :]) / np.where(valid, h3, 1.0)[..., None, None]
        L = np.where(valid[..., None, None], L, 0.0)
        Rm = np.where(valid, G * eta / ah3 + (gn + G) * eta * eta / (ah3 * (1 - eta)), 0.0)
        E = np.hypot(ec[..., 0], ec[..., 1]) + np.einsum("bnk,bk->bn", np.sqrt(np.sum(L * L, axis=2)), r)
    c = np.sqrt(c2)
    infeasible = np.any(forced & (hi < c), axis=1) | np.any(need & (lo >= c), axis=1)
    out = ~forced & (lo >= c)
    quad = valid & ~forced & ~out & ((hi < c) | need)
    amb = ~forced & ~out & ~quad
    fixed = np.sum(np.where(forced | out, c2, 0.0), axis=1) + np.sum(np.where(amb, lo * lo, 0.0), axis=1)
    q_lb = _box_ls(ec, L, quad, r) - 2 * np.sum(np.where(quad, E * Rm, 0.0), axis=1)
    q_lb = np.maximum(q_lb, np.sum(np.where(quad, lo * lo, 0.0), axis=1))
    with np.errstate(invalid="ignore"):
        bound = np.where(infeasible, np.inf, (fixed + q_lb) * MARGIN_REL)
        d2 = np.where(valid, ec[..., 0] ** 2 + ec[..., 1] ** 2, np.inf)
        f_centre = np.sum(np.minimum(d2, c2), axis=1)
    with np.errstate(all="ignore"):        # pixel motion per direction (every view, also where h_3 may vanish)
        motion = (colg + np.hypot(ec[..., 0], ec[..., 1])[..., None] * absJ3) / np.maximum(ah3, R3)[..., None]
    effect = np.sum(np.where(np.isfinite(motion), motion, 0.0), axis=1) * r
    return bound, f_centre, np.argmax(effect, axis=1)


class _Patterns:
    """The patterns (a, b) of one problem (module docstring): frames, forced outliers, root cells."""

    def __init__(self, C, x, c2, X0, order, ub, meets, d2_direct=None):
        self.N = len(C)
        self.d2_direct = d2_direct                    # the frames' check (frame_agrees), None: unchecked
        c = np.sqrt(c2)
        pos_c2 = c2[order]
        self.frames, self.ref = {}, []
        self.forced, self.need, self.roots = [], [], []
        self.floor = math.inf                         # bound of the skipped patterns (forced cost meets UB)
        self.ok = True
        self._K = self._slot = None
        for pb in range(1, self.N):
            least = float(np.sum(pos_c2[:pb]) - np.max(pos_c2[:pb]))     # no pattern from pb on costs less
            if meets(least * MARGIN_REL):
                self.floor = min(self.floor, least * MARGIN_REL)
                break
            for pa in range(pb):
                cost = float(np.sum(pos_c2[:pb]) - pos_c2[pa])
                if meets(cost * MARGIN_REL):
                    self.floor = min(self.floor, cost * MARGIN_REL)
                    continue
                a, b = int(order[pa]), int(order[pb])
                ref = self._reference(C, x, c, X0, a, b)
                if ref is None:
                    self.ok = False
                    return
                view, W = ref                           # the reference: a, or b where only b bounds w
                f = np.zeros(self.N, bool)
                f[order[:pb]] = True
                f[a] = False                            # the forced outliers: every view before b but a
                n = np.zeros(self.N, bool)
                n[[a, b]] = True
                self.ref.append(view)
                self.forced.append(f)
                self.need.append(n)
                self.roots.append((np.zeros(3), np.array([c[view], c[view], W])))
        self.forced, self.need = np.array(self.forced).reshape(-1, self.N), np.array(self.need).reshape(-1, self.N)

    def _reference(self, C, x, c, X0, a: int, b: int):
        """(reference view, W) of the pattern of inliers a, b: a with w bounded by b, else b with w bounded by a
        (module docstring); None when neither bounds w (both centres project within c of the other's point)."""
        for ref, other in ((a, b), (b, a)):
            if ref not in self.frames:
                fr = frame(C, x, X0, ref)
                ok = fr is not None and (self.d2_direct is None or frame_agrees(fr, self.d2_direct))
                if fr is not None and not ok:
                    log.debug("cell search: the frame of view %d disagrees with the direct distances", ref)
                self.frames[ref] = fr if ok else None
            if self.frames[ref] is None or not math.isfinite(c[ref]):
                continue
            W = w_bound(self.frames[ref][0][other], c[other], c[ref])
            if math.isfinite(W):
                return ref, W
        return None

    def evaluate(self, pat: np.ndarray, qc: np.ndarray, r: np.ndarray, c2: np.ndarray):
        if self._K is None:                           # the frames stacked once, indexed per cell
            refs = sorted(set(self.ref))
            self._K = np.stack([self.frames[a][0] for a in refs])
            self._slot = np.array([refs.index(a) for a in self.ref], dtype=int)
        K = self._K[self._slot[pat]]
        return evaluate_cells(K, c2, self.forced[pat], self.need[pat], qc, r)

    def world(self, p: int, qc: np.ndarray, X0: np.ndarray):
        """The world point of the cell centre q_c in pattern p (None at infinity)."""
        T = self.frames[self.ref[p]][1]
        Xh = T @ np.array([qc[0], qc[1], 1.0, qc[2]])
        if not abs(Xh[3]) > 0:
            return None
        X = Xh[:3] / Xh[3] + X0
        return X if np.all(np.isfinite(X)) else None


def frame_agrees(fr, d2_direct: np.ndarray) -> bool:
    """A frame (K, T) reproduces sum_i d_i^2 at the best candidate X0 (q = T^-1 (0, 0, 0, 1)) within
    :data:`FRAME_CHECK_REL` of the direct (compensated) distances."""
    K, T = fr
    q = np.linalg.solve(T, np.array([0.0, 0.0, 0.0, 1.0]))      # X0 itself: X~ - X0 w = (0, 0, 0, w)
    if not abs(q[2]) > 0:
        return False
    h = K @ (q / q[2])
    with np.errstate(all="ignore"):
        d2 = (h[:, 0] ** 2 + h[:, 1] ** 2) / h[:, 2] ** 2
    ok = np.isfinite(d2_direct)
    s = float(np.sum(d2_direct[ok]))
    return bool(np.all(np.isfinite(d2[ok])) and abs(float(np.sum(d2[ok])) - s) <= FRAME_CHECK_REL * max(s, 1e-300))


def cell_lower_bound(C, x, c2, X0, order, ub_fn, meets, offer, deadline, max_cells: int = MAX_CELLS):
    """A valid lower bound of f_TLS* (module docstring) as a :class:`CellBound`, or None where the patterns cannot be
    bounded.

    ``ub_fn()`` gives the current best value, ``meets(lb)`` the caller's pruning rule, ``offer(X)`` takes a candidate
    (it may lower ub_fn()), ``deadline`` stops the search (bound then from the open cells)."""
    C, x, c2, X0 = np.asarray(C, float), np.asarray(x, float), np.asarray(c2, float), np.asarray(X0, float)
    with np.errstate(all="ignore"):
        P0 = homogeneous_images(C, np.append(X0, 1.0))
        d2_direct = np.sum((P0[:, :2] / P0[:, 2:] - x) ** 2, axis=1)
    pats = _Patterns(C, x, c2, X0, order, ub_fn(), meets, d2_direct)
    if deadline.expired:
        return None
    if not pats.ok:
        log.debug("cell search refused: a pattern's inverse depth is unbounded (or its frames fail)")
        return None
    floor = min(pats.floor, float(np.sum(c2) - np.max(c2)) * MARGIN_REL)   # X with at most one inlier
    rule = _Threshold(meets, ub_fn)
    heap, tick = [], 0
    n_pat = len(pats.roots)
    if n_pat:
        pat = np.arange(n_pat)
        qc = np.array([q for q, _ in pats.roots])
        r = np.array([rr for _, rr in pats.roots])
        bound, _, dim = pats.evaluate(pat, qc, r, c2)
        floor, tick = _push(heap, tick, floor, pat, qc, r, bound, dim, rule)
    cells = n_pat
    while heap:
        if cells >= max_cells or deadline.expired:
            break
        t, ub = rule.threshold(), ub_fn()
        batch = [heapq.heappop(heap) for _ in range(min(BATCH, len(heap)))]
        keep = [it for it in batch if it[0] < t]
        floor = min([floor] + [it[0] for it in batch if t <= it[0] < ub])
        if not keep:
            continue
        pat = np.repeat([it[2] for it in keep], 2)
        qc = np.repeat(np.array([it[3] for it in keep]), 2, axis=0)
        r = np.repeat(np.array([it[4] for it in keep]), 2, axis=0)
        k = np.repeat([it[5] for it in keep], 2)
        idx = np.arange(len(pat))
        r[idx, k] *= 0.5
        qc[idx, k] += np.where(idx % 2 == 0, -1.0, 1.0) * r[idx, k]
        bound, fc, dim = pats.evaluate(pat, qc, r, c2)
        cells += len(pat)
        best = int(np.argmin(fc))
        if fc[best] < ub * (1 - 1e-9):
            offer(pats.world(int(pat[best]), qc[best], X0))
        floor, tick = _push(heap, tick, floor, pat, qc, r, bound, dim, rule)
    open_lb = heap[0][0] if heap else math.inf
    log.debug("cell search: %d cells, %d open, floor %.6g, open %.6g, UB %.6g", cells, len(heap), floor, open_lb,
              ub_fn())
    return CellBound(min(ub_fn(), floor, open_lb), cells, bool(heap) and cells >= max_cells)


@dataclass(frozen=True)
class CellBound:
    """The cell search's outcome: its lower bound of f_TLS*, the cells evaluated, and whether it stopped at
    :data:`MAX_CELLS` with cells open (the search then cannot close with its budget)."""
    lb: float
    cells: int
    exhausted: bool


class _Threshold:
    """The pruning rule as a threshold: ``meets`` is monotone in the bound for a fixed UB, so the least bound that
    meets (bisection, cached per UB) decides every cell with one comparison."""

    def __init__(self, meets, ub_fn):
        self.meets, self.ub_fn, self.ub, self.t = meets, ub_fn, None, math.inf

    def threshold(self) -> float:
        ub = self.ub_fn()
        if ub != self.ub:
            self.ub, self.t = ub, self._search(ub)
        return self.t

    def _search(self, ub: float) -> float:
        if not math.isfinite(ub):
            return math.inf
        if self.meets(0.0):
            return 0.0
        lo, hi = 0.0, ub                                  # meets(lo) False, meets(hi) True (lb >= UB)
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if not lo < mid < hi:
                break
            lo, hi = (lo, mid) if self.meets(mid) else (mid, hi)
        return hi


def _push(heap, tick, floor, pat, qc, r, bound, dim, rule):
    """Push the cells that do not meet UB; the others lower the floor (if below UB)."""
    t, ub = rule.threshold(), rule.ub_fn()
    met = bound >= t
    below = met & (bound < ub)
    if np.any(below):
        floor = min(floor, float(np.min(bound[below])))
    for j in np.nonzero(~met)[0]:
        heapq.heappush(heap, (float(bound[j]), tick, int(pat[j]), qc[j], r[j], int(dim[j])))
        tick += 1
    return floor, tick


def search_bound(search) -> CellBound | None:
    """The cell bound of a :class:`tritools.solve.robust.TlsSearch` with point regions (None where it does not apply:
    other regions, :data:`ENABLED` off, no candidate, or patterns that cannot be bounded)."""
    if not (ENABLED and search.points and search.best_X is not None and MIN_VIEWS <= search.N <= MAX_VIEWS) \
            or search.deadline.expired:
        return None
    with np.errstate(all="ignore"):
        ratio = np.sqrt(search.sq_distances(search.best_X)) / search.c
    order = np.argsort(np.where(np.isfinite(ratio), ratio, np.inf), kind="stable")
    lb = cell_lower_bound(search.C, search.x, search.c2, search.best_X, order, lambda: search.best_f,
                          search.meets, search.offer, search.deadline,
                          max_cells=min(MAX_CELLS, MAX_VIEW_CELLS // max(search.N, 1)))
    return lb
