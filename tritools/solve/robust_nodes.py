"""The node bounds of the TLS branch and bound (:class:`tritools.solve.robust.TlsSearch`, a mixin).

A node fixes inliers I and outliers O and leaves U undecided; for the X of the node, with s = sum_{i in I} d_i(X)^2
(module docstring of :mod:`tritools.solve.robust`),

    LB(node) = min( UB, c^2(O) + min_{s in [L2LB(I), min(c^2(I), UB - c^2(O))]}
                                   [ s + sum_{u in U} min(c_u^2, max(0, a_u - s)) ] ),   a_u = L2LB(I + {u}),

a piecewise-linear minimum in s (:func:`lookahead_bound`); the root bound min(L2LB(V), min_i c_i^2) and the
leave-one-out bound min(L2LB(V), min_j [c_j^2 + min(L2LB(V - j), min_{i != j} c_i^2)]) are its first two levels.
"""
from __future__ import annotations

import math

import numpy as np

from .robust_bounds import ROUND_DOWN
from .robust_report import PRUNE_SHARE, guards_pass, reported_resolution

__all__ = ["NodeBounds", "lookahead_bound"]


def lookahead_bound(s_lo: float, s_hi: float, a: np.ndarray, c2: np.ndarray) -> float:
    """min over s in [s_lo, s_hi] of g(s) = s + sum_u min(c2_u, max(0, a_u - s)) (+inf for an empty interval).

    g is piecewise linear and continuous with breakpoints at a_u and a_u - c2_u, so its minimum over the
    interval is at an end or at a breakpoint inside it."""
    if not s_hi >= s_lo:
        return math.inf
    a, c2 = np.asarray(a, float), np.asarray(c2, float)
    cand = np.concatenate([[s_lo, s_hi], a, a - c2])
    cand = cand[(cand >= s_lo) & (cand <= s_hi)]
    g = cand + np.sum(np.minimum(c2[None, :], np.maximum(0.0, a[None, :] - cand[:, None])), axis=1)
    return float(np.min(g))


class NodeBounds:
    """The node bounds of :class:`tritools.solve.robust.TlsSearch` and its pruning rule :meth:`meets` (its
    attributes: N, c, c2, x, regions, points, tol, scale, best_f, best_S, bounds, anchors, anchor_a, _resolved; its
    methods need, offer_new)."""

    def meets(self, lb: float) -> bool:
        """Is a lower bound good enough to prune: it exceeds UB, or it meets UB under the certificate rule on this
        search's scale and within :data:`~tritools.solve.robust_report.PRUNE_SHARE` of the report's own gap guard
        (:func:`~tritools.solve.robust_report.guards_pass`)?  The guard matters where the scale min(c^2, rho^2) is
        large (rho inflated by a wrong match): a node pruned by the absolute part of the rule alone would leave a gap
        that the report refuses (a 0.05 px^2 inlier pair under c^2 = 40000 px^2: gamma gap 5e-5 px against a 9e-6 px
        resolution), where its leaf's own bound closes it."""
        ub = self.best_f
        if lb >= ub:
            return True
        if not self.tol.certified_one(lb, ub, self.scale):
            return False
        N = self.N
        return guards_pass(math.sqrt(max(lb, 0.0) / (2 * N)), math.sqrt(ub / (2 * N)), N, self.tol, self.resolved,
                           PRUNE_SHARE)

    @property
    def resolved(self) -> float:
        """The report's gamma resolution of this problem: the coordinates' resolution capped by the thresholds' scale
        (:func:`~tritools.solve.robust_report.reported_resolution`)."""
        if self._resolved is None:
            centres = self.x if self.points else np.array([r.center for r in self.regions])
            self._resolved = reported_resolution(centres, self.c, self.tol, self.C)
        return self._resolved

    def leave_one_out_bound(self) -> float:
        """f_TLS* >= min(L2LB(V), min_j [c_j^2 + min(L2LB(V - j), min_{i != j} c_i^2)]) over the views V: an X
        with every view an inlier costs L2*(V); otherwise some j is an outlier of X, which pays c_j^2 plus, on the
        other views, at least the root bound of the problem without j (:meth:`root_bound`).  Unknown subset
        bounds count 0; rounded down."""
        full = frozenset(range(self.N))
        c2 = self.c2
        terms = [self.bounds.bound(full) if self.bounds.known(full) else 0.0]
        for j in range(self.N):
            S = full - {j}
            lb = self.bounds.bound(S) if self.bounds.known(S) else 0.0
            rest = float(np.min(np.delete(c2, j)))
            terms.append((c2[j] + min(lb, rest)) * ROUND_DOWN)
        return float(min(terms))

    def root_bound(self) -> float:
        """f_TLS* >= min(L2LB(all views), min_i c_i^2) (module docstring)."""
        return min(self.bounds.bound(frozenset(range(self.N))), float(np.min(self.c2)))

    def node_bound(self, I: frozenset, c2_out: float, U: list, lb_I: float, a: np.ndarray, refine: bool = True):
        """(bound, lb_I, a) of a node (module docstring).  ``lb_I`` and ``a`` (N,) are inherited lower bounds of
        L2*(I) and of L2*(I + {u}) (a parent's bound of a subset is one of every superset).  The bound is first
        taken with them; only when it does not prune and ``refine`` are the exact sub-bounds computed, and only
        where they can matter (a_u >= s_max + c_u^2 already gives the term c_u^2)."""
        if len(I) >= 2 and self.bounds.known(I):
            lb_I = max(lb_I, self.bounds.bound(I))
        a = np.maximum(a, lb_I)
        if self.anchors is not None and self.anchors <= I:
            a = np.maximum(a, self.anchor_a)          # L2*(I + {u}) >= L2*(anchors + {u})
        bound = self._bound(I, c2_out, U, lb_I, a)
        if self.meets(bound) or not refine:
            return bound, lb_I, a
        if len(I) >= 2 and not self.bounds.known(I):
            yield from self.need([I])
            self.offer_new()
            lb_I = max(lb_I, self.bounds.bound(I))
            a = np.maximum(a, lb_I)
        if not I or not U or self.meets(c2_out + lb_I):
            return self._bound(I, c2_out, U, lb_I, a), lb_I, a
        # the views the best candidate calls outliers first (their terms c_u^2 usually prune), then the rest
        best_S = self.best_S
        for stage in (False, True):
            hi = min(float(np.sum(self.c2[list(I)])), self.best_f - c2_out)
            Ua = np.array([u for u in U if (u in best_S) == stage])
            open_ = Ua[a[Ua] < hi + self.c2[Ua]] if Ua.size else Ua
            if open_.size:
                subsets = [I | {int(u)} for u in open_]
                yield from self.need(subsets)
                self.offer_new()
                a = a.copy()
                a[open_] = np.maximum(a[open_], [self.bounds.bound(S) for S in subsets])
            bound = self._bound(I, c2_out, U, lb_I, a)
            if self.meets(bound):
                break
        return bound, lb_I, a

    def anchor_bounds(self, order: np.ndarray):
        """L2 bounds of the triples (first two views of the order) + {u}, one batch: every node whose I holds both
        anchors inherits L2*(I + {u}) >= L2*(anchors + {u})."""
        if self.N < 3:
            return
        anchors = frozenset(int(v) for v in order[:2])
        triples = [anchors | {u} for u in range(self.N) if u not in anchors]
        yield from self.need(triples)
        self.offer_new()
        self.anchors = anchors
        self.anchor_a = np.array([0.0 if u in anchors else self.bounds.bound(anchors | {u}) for u in range(self.N)])

    def _bound(self, I: frozenset, c2_out: float, U: list, lb_I: float, a: np.ndarray) -> float:
        """The node bound from the given sub-bounds (no new sub-problems)."""
        base = c2_out + lb_I
        if not I or not U:
            return min(self.best_f, base)
        hi = min(float(np.sum(self.c2[list(I)])), self.best_f - c2_out)
        Ua = np.array(U)
        g = lookahead_bound(lb_I, hi, a[Ua], self.c2[Ua])
        return min(self.best_f, max(base, (c2_out + g) * ROUND_DOWN))

    def bound_uncapped(self, I: frozenset, c2_out: float, U: list, lb_I: float, a: np.ndarray) -> float:
        """:meth:`_bound` with s over all of [L2LB(I), c^2(I)] and no min with UB: a lower bound of the node's own
        f_TLS optimum that does not lean on UB (a cover's split, :func:`tritools.solve.robust_suspects._told`, lowers
        it by other coordinates' round-off than UB's)."""
        base = c2_out + lb_I
        if not I or not U:
            return base
        Ua = np.array(U)
        g = lookahead_bound(lb_I, float(np.sum(self.c2[list(I)])), a[Ua], self.c2[Ua])
        return max(base, (c2_out + g) * ROUND_DOWN)

    def child_bounds(self, v: int, lb_I: float, a: np.ndarray):
        """Inherited bounds of the child I + {v}: L2*(I + {v}) >= a_v, L2*(I + {v, u}) >= a_u and >= L2*({v, u})."""
        pair = np.array([self.bounds.bound(frozenset((v, u))) if self.bounds.known(frozenset((v, u))) else 0.0
                         for u in range(self.N)])
        return max(lb_I, a[v]), np.maximum(np.maximum(a, pair), a[v])
