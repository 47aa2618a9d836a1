"""Single robust calls of three (and two) point views: the enumeration of every inlier set in one pass, no stack.

With N = 3 views the inlier sets of at least two views are the three pairs and all views, so (the identity of
:mod:`tritools.solve.robust`, the terms of :mod:`tritools.solve.robust_enum`)

    f*_TLS = min( L2*(V),  min_k [L2*(V - k) + c_k^2],  min_i c^2(V - i),  c^2(V) ),

and the superadditive closure of L2LB(V) is its maximum with the largest pair bound (V = pair + one view, whose
L2* is 0).  :func:`three_view_tls` takes the steps of :class:`tritools.solve.robust_enum_run._Group` for one
problem with the same functions and rules -- the frame (:func:`~tritools.solve.robust_enum.enum_frame`), the four
candidates in one masked stack (:func:`~tritools.solve.robust_enum.enum_candidates`), the best of them offered and
refined on its inlier set (:func:`~tritools.solve.robust_enum.refine_row_one`, inlier set -> its L2 optimum ->
inlier set, at most :data:`~tritools.solve.robust_enum_run.LO_ROUNDS` rounds), the Lagrangian bounds
(:func:`~tritools.solve.robust_enum.enum_bounds_rows`) of the sets whose c^2(V - S) alone does not meet UB and of
the pairs holding a view outside the best inlier set (one stacked verification: the whole set's bound with them,
where the stack of many problems waits for the closure first), LB by
:func:`~tritools.solve.robust_enum_run.lower_bounds`, the decision at the floor of the decision scale and else,
after the failing rows are refined on their own sets and bounded again (:meth:`_ThreeViews._second_chance`) and the
sets inside a term that does not meet UB are bounded, at the documented scale -- without the
bookkeeping that a stack of many problems needs (masks over problems, ranking across them, the staged order).
Measured against the stack of one: benchmarks/RESULTS.md (wave 8, single robust calls at N = 3-7).

Returns None where the enumeration does not decide (the caller runs the branch and bound, which starts from the
candidates offered here): wherever the stack of one decides, this path decides too (it bounds the same rows or more,
tests/test_robust_three_path.py).  Every bound is the stack's (the same functions), so the rigour is the stack's.
"""
from __future__ import annotations

import logging

import numpy as np

from ..model.normalize import SCALE_BOUNDS
from . import robust_enum as enum
from .robust_bounds import ROUND_DOWN
from .robust_costs import point_distances2
from .robust_enum_run import LO_ROUNDS, eligible, lower_bounds
from .robust_report import enumerated_result, outside_split
from .robust_two import optimum_candidate, ray_offers

__all__ = ["two_view_tls", "three_view_tls", "three_terms", "three_lower_bound", "exact_terms",
           "three_rest", "VIEWS", "POLISH_STEPS"]

log = logging.getLogger(__name__)

#: the view count of this path.
VIEWS = 3
#: Levenberg-Marquardt steps polishing each row's DLT start (the stack's POLISH_STEPS is 5): the best row is then
#: refined to convergence on its inlier set and every row whose bound fails on its own set (:meth:`_second_chance`),
#: so the other rows' polish only has to rank them.  Measured (protocol scenes, one wrong match, 1 and 5 px, 300
#: single calls per setting, median CPU, settings interleaved): 5 steps 2.48-2.52 ms, 2 steps 2.31-2.34, 1 step
#: 2.18-2.25, 0 steps 2.22-2.25; scenes left to the branch and bound 23 / 21 / 21 / 22 of 300; every one certified.
POLISH_STEPS = 1


def two_view_tls(search):
    """The TLS result of one :class:`tritools.solve.robust.TlsSearch` of two point views (:class:`_TwoViews`), or
    None (the caller runs the search).  Searches of other view counts or regions get None too."""
    return _single(search, _TwoViews)


def three_view_tls(search):
    """The TLS result of one :class:`tritools.solve.robust.TlsSearch` of three point views (module docstring), or
    None (the caller runs the search).  Searches of other view counts or regions get None too."""
    return _single(search, _ThreeViews)


def _single(search, path):
    """``path(search).run()`` for a search of ``path.views`` point views (None otherwise, or where it fails on
    degenerate data)."""
    if search.N != path.views or not eligible(search):
        return None
    try:
        return path(search).run()
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        log.debug("%d-view enumeration failed", path.views, exc_info=True)
        return None


class _ThreeViews:
    """One search's rows: the sets of :func:`~tritools.solve.robust_enum.subset_masks` (3) -- the pairs, then all
    views."""

    views = VIEWS

    def __init__(self, search):
        self.s = search
        self.W = enum.subset_masks(self.views)
        self.size = self.W.sum(axis=1)
        c2 = search.c2.tolist()
        self.rest = np.array(self._rest(c2))           # c^2(V - S); inf: c_i = inf
        self.lb = np.zeros(len(self.W))
        self.bounded = np.zeros(len(self.W), bool)
        self.F = self.E = None
        self.refined = np.zeros(len(self.W), bool)     # rows whose candidate was refined on its own set
        from .robust import scale_from

        self.floor = scale_from(SCALE_BOUNDS[1], search.c2)
        self.exact = exact_terms(c2)                  # the terms of |S| <= 1 (they do not change)

    def run(self):
        s = self.s
        framed = enum.enum_frame(s.C, s.x, s.c2)
        if framed is None:
            return None
        self.frame, self.Cn = framed
        self.Xn = self._candidates()
        self._offer()
        if s.best_X is None or s.deadline.expired:
            return None
        self._bound(self._open() | self._outside_pairs())
        lb = self._lower_bound()
        if not self._meets_at_floor(lb) and not s.deadline.expired:
            lb = self._second_chance(lb)
        if not self._meets_at_floor(lb) and not s.deadline.expired:
            lb = self._ascend_all(lb)
        if not self._meets_at_floor(lb) and not s.deadline.expired:
            lb = self._solve_all(lb)
        if self._meets_at_floor(lb):
            s.set_normalization_scale(SCALE_BOUNDS[1])       # met at the floor: met at the documented scale
            return self._result(lb)
        if s.deadline.expired:
            return None
        more = ~self.bounded & self._feeding()
        if more.any():
            self._bound(more)
            lb = self._lower_bound()
        return self._result(lb) if s.meets(lb) else None      # (the search's rule: the report's guard too)

    def _candidates(self) -> np.ndarray:
        """The rows' normalised candidates (:func:`~tritools.solve.robust_enum.enum_candidates`)."""
        return enum.enum_candidates(self.Cn, self.W, POLISH_STEPS)

    def _meets_at_floor(self, lb: float) -> bool:
        """LB meets UB under the rule at the floor of the decision scale, without contradicting it there."""
        s = self.s
        return s.tol.certified_one(lb, s.best_f, self.floor) and not s.tol.contradicts_one(lb, s.best_f, self.floor)

    def _outside_pairs(self) -> np.ndarray:
        """The pairs holding a view outside the best inlier set, where UB exceeds min c^2 (they feed the closure of
        the sets holding that view)."""
        s = self.s
        best = np.array([i in s.best_S for i in range(self.views)])
        inside = ~(self.W & ~best[None]).any(axis=1)
        return (self.size == 2) & ~inside & (s.best_f > np.min(s.c2))

    # ------------------------------------------------------------------ steps
    def _offer(self) -> None:
        """Offer the best candidate (ranked by f_TLS), refined on its inlier set S, its refined point put in the row
        of S; again from a new best with another inlier set (:meth:`_Group._offer` for one problem)."""
        s, fr = self.s, self.frame
        rows = np.nonzero(np.isfinite(self.Xn).all(axis=1))[0]
        if not rows.size:
            return
        world = fr.origin + fr.depth * self.Xn[rows]
        d2 = point_distances2(s.C, s.x, world)
        r = int(np.argmin(np.sum(np.minimum(d2, s.c2[None]), axis=1)))      # (ties: the first, as the stack)
        X, S = world[r], np.nonzero(d2[r] < s.c2)[0].tolist()
        s.offer(X)
        refined = set()
        for _ in range(LO_ROUNDS):                      # inlier set -> its L2 optimum -> inlier set
            if len(S) < 2 or frozenset(S) in refined:
                return
            refined.add(frozenset(S))
            Xr, ok = enum.refine_row_one(self.Cn, fr.normalized_point(X), S)
            if not ok:
                return
            Xw = fr.world_point(Xr)
            s.offer(Xw)
            row = enum.row_of(self.views)[sum(1 << i for i in S)]
            self.Xn[row], self.refined[row] = Xr, True
            if s.best_S == frozenset(S) or not np.array_equal(s.best_X, Xw):
                return
            X, S = s.best_X, sorted(s.best_S)                # a new best with another inlier set

    def _second_chance(self, lb: float) -> float:
        """The rows whose term does not meet UB, refined to convergence on their own sets (their polished candidate
        may be short of the set's L2 optimum, and a Lagrangian bound taken there fails or falls short), offered
        (UB may fall: a set's optimum the polish did not reach) and bounded again; LB after."""
        s = self.s
        failing = self._failing() & ~self.refined
        if not failing.any():
            return lb
        m = np.nonzero(failing & np.isfinite(self.Xn).all(axis=1))[0]
        self.refined[failing] = True
        if not m.size:
            return lb
        again = np.zeros(len(self.W), bool)
        for row in m.tolist():
            Xr, ok = enum.refine_row_one(self.Cn, self.Xn[row], np.nonzero(self.W[row])[0].tolist())
            if ok:
                self.Xn[row] = Xr
                s.offer(self.frame.world_point(Xr))
                again[row] = True
        old = self.lb.copy()
        self.bounded &= ~again
        self._bound(again)
        self.lb = np.maximum(self.lb, old)             # both bounds are valid: the larger
        return self._lower_bound()

    def _ascend_all(self, lb: float) -> float:
        """The row of all three views, when its term does not meet UB: its bound by the best degree-2 certificate
        (:func:`~tritools.solve.robust_enum.ascended_bound`, climbing to UB) instead of the one at its candidate
        (one wrong match: the candidate's KKT multipliers give no bound, the dual's maximum often exceeds UB, and
        the search's batched SDP of the same certificate is not needed); LB after."""
        s, row = self.s, len(self.W) - 1
        if not (self._failing()[row] and np.isfinite(self.Xn[row]).all()):
            return lb
        self._fundamentals()
        bound = enum.ascended_bound(self.Cn, self.F, self.defined, self.W[row], self.Xn[row], self.frame.scale,
                                    s.tol, s.best_f, self.E)
        self.lb[row] = max(self.lb[row], bound)          # both bounds are valid: the larger
        return self._lower_bound()

    def _solve_all(self, lb: float) -> float:
        """The row of all three views, when it alone keeps LB below UB: its sub-problem solved as a stack solves its
        last open set (:meth:`~tritools.solve.robust_bounds.SubsetBounds.solve_full`: Theorem 1 at delta = 4 first,
        stopping once its rigorous bound reaches UB), here rather than after the search's set-up; its estimate
        offered (UB may fall); LB after."""
        s, row = self.s, len(self.W) - 1
        failing = self._failing()
        if not failing[row] or failing[:row].any():
            return lb
        X = self.frame.world_point(self.Xn[row]) if np.isfinite(self.Xn[row]).all() else None
        b, Xs = s.bounds.solve_full(frozenset(range(self.views)), s.best_f, X)
        self.lb[row] = max(self.lb[row], b)
        if Xs is not None:
            s.offer(Xs)
        return self._lower_bound()

    def _failing(self) -> np.ndarray:
        ub, tol = self.s.best_f, self.s.tol
        return np.array([t < ub and not tol.certified_one(t, ub, self.floor) for t in self._terms()])

    def _bound(self, rows: np.ndarray) -> None:
        """The Lagrangian bounds of the rows not bounded yet, one stacked verification (the fundamental matrices
        once)."""
        rows = rows & ~self.bounded
        if not rows.any():
            return
        self.bounded |= rows
        self._fundamentals()
        m = np.nonzero(rows)[0]
        R = len(m)
        self.lb[m], _ = enum.enum_bounds_rows(
            np.broadcast_to(self.Cn, (R,) + self.Cn.shape), np.broadcast_to(self.F, (R,) + self.F.shape),
            np.broadcast_to(self.defined, (R,) + self.defined.shape), self.W[m], self.Xn[m],
            np.full(R, self.frame.scale), self.s.tol, accepted=False,
            errors=np.broadcast_to(self.E, (R,) + self.E.shape))

    def _fundamentals(self) -> None:
        """The view pairs' fundamental matrices (``F``, ``defined``), computed once."""
        if self.F is None:
            F, defined, E = enum.fundamentals(self.s.C[None], self.Cn[None])
            self.F, self.defined, self.E = F[0], defined[0], E[0]

    @staticmethod
    def _rest(c2: list) -> list:
        return three_rest(c2)

    def _terms(self) -> list:
        return three_terms(self.lb.tolist(), self.rest.tolist())

    def _lower_bound(self) -> float:
        return three_lower_bound(self.s.best_f, self._terms(), self.exact)

    def _open(self) -> np.ndarray:
        """The rows whose term c^2(V - S) alone does not meet UB at the floor scale (finite only)."""
        ub = self.s.best_f
        met = (self.rest >= ub) | np.asarray(self.s.tol.certified(self.rest, ub, self.floor), bool)
        return ~met & np.isfinite(self.rest)

    def _feeding(self) -> np.ndarray:
        """The rows inside a row whose term does not meet UB at the floor scale."""
        return (enum.subset_of(self.views) & self._failing()[None]).any(axis=1)

    def _result(self, lb: float):
        self.s.enum_terms = self.frame.frame_terms             # the frame of every bound the enumeration used
        split = outside_split(self.W, self._terms(), [i not in self.s.best_S for i in range(self.views)], self.s.c2,
                              self.lb)
        return enumerated_result(self.s, lb, self.bounded.sum(), len(self.W), split)



class _TwoViews(_ThreeViews):
    """Two point views: the one set of at least two views is all views, f*_TLS = min(L2*(V), c_1^2, c_2^2)
    (:mod:`tritools.solve.robust_two`).  The candidate is the closed-form optimum of both views
    (:func:`~tritools.solve.robust_two.optimum_candidate`; the enumeration's where it does not apply); after its
    offer, it is refined to convergence on both views and, unless UB is already at most min c_j^2, each view's ray is
    sampled (:func:`~tritools.solve.robust_two.ray_offers`), as a stack's two-view problems take them
    (:func:`~tritools.solve.robust_two.two_view_rays`); no all-views sub-problem (the stack solves none for two views
    either)."""

    views = 2
    rays_done = False
    closed_form = False

    @staticmethod
    def _rest(c2: list) -> list:
        """c^2(V - V) rounded down: the masked sum of :func:`three_rest` for the one row (0)."""
        return [(0.0 + 0.0) * ROUND_DOWN]

    def _terms(self) -> list:
        """The one term L2LB(V) + 0, rounded down (a split of two views into parts of one view closes to 0: the
        stack's closure leaves the bound as it is)."""
        return [(float(self.lb[0]) + float(self.rest[0])) * ROUND_DOWN]

    def _candidates(self) -> np.ndarray:
        """The closed-form L2 optimum of both views (:func:`~tritools.solve.robust_two.optimum_candidate`), else
        the enumeration's candidate."""
        self._fundamentals()
        if self.defined[0]:
            Xn = optimum_candidate(self.Cn, self.F[0])
            if Xn is not None:
                self.closed_form = True
                return Xn[None]
        return super()._candidates()

    def _offer(self) -> None:
        super()._offer()
        s = self.s
        if s.best_X is None:
            return
        if not self.refined[0] and np.isfinite(self.Xn[0]).all():
            Xr, ok = enum.refine_row_one(self.Cn, self.Xn[0], [0, 1])
            if ok:
                self.Xn[0], self.refined[0] = Xr, True
                s.offer(self.frame.world_point(Xr))
        if not (self.refined[0] and s.best_f <= float(np.min(s.c2))):
            self._rays()
        # else: a ray sample costs min(d_j^2, c_j^2) >= min(L2*, c_j^2) >= L2*, and UB is L2 at both views' refined
        # optimum: the rays wait for a decision that fails (:meth:`_solve_all`)

    def _rays(self) -> None:
        """Each view's ray sampled (:func:`~tritools.solve.robust_two.ray_offers`), its best sample offered."""
        s = self.s
        self.rays_done = True
        for _, X in ray_offers(s.C[None], s.x[None], s.c2[None], np.array([s.best_f]), np.array([self.floor]),
                               s.tol):
            if np.isfinite(X).all():
                s.offer(X)

    def _solve_all(self, lb: float) -> float:
        """No all-views sub-problem (the stack solves none for two views either); the rays :meth:`_offer` left,
        where LB does not meet UB yet (the cost at both views' optimum may be far above L2* where that optimum sits
        at a camera centre: an observation next to its epipole); LB after."""
        if not self.rays_done:
            self._rays()
        if self.closed_form and not self._meets_at_floor(self._lower_bound()):
            self._enumerated_candidate()
        return self._lower_bound()

    def _enumerated_candidate(self) -> None:
        """The enumeration's candidate of both views (the DLT, polished) offered, refined, offered and bounded (the
        larger of the two valid bounds kept), where the closed form's does not decide: its optimum at a camera
        centre (an observation next to its epipole) is a stationary point the refinement stays at, where the
        world's cost is far above the frame's; the search that may follow starts from both."""
        self.closed_form = False
        Xn = super()._candidates()[0]
        if not np.isfinite(Xn).all():
            return
        self.s.offer(self.frame.world_point(Xn))
        Xr, ok = enum.refine_row_one(self.Cn, Xn, [0, 1])
        if not ok:
            return
        self.s.offer(self.frame.world_point(Xr))
        old = self.lb.copy()
        self.Xn[0], self.bounded[0] = Xr, False
        self._bound(np.ones(1, bool))
        self.lb = np.maximum(self.lb, old)


def three_terms(lb: list, rest: list) -> list:
    """The scalar twin of :func:`~tritools.solve.robust_enum_run.closed_terms` for one problem of three views, on
    floats, bit for bit (tests/test_robust_three_path.py): the rows of :func:`~tritools.solve.robust_enum.subset_masks`
    (the pairs {0, 1}, {0, 2}, {1, 2}, then all views) with their bounds ``lb`` (>= 0) and c^2(V - S) ``rest``.  The
    closure of a pair is its own bound (its parts are single views, L2* = 0); that of all views is the largest of its
    own and of its splits {0} + {1, 2}, {0, 1} + {2}, {0, 2} + {1} (:func:`~tritools.solve.robust_enum.closure`'s order
    and operations); each term (L2LB(S) + c^2(V - S)) rounded down."""
    l01, l02, l12, l_all = lb
    closed_all = max(l_all, (0.0 + l12) * ROUND_DOWN, (l01 + 0.0) * ROUND_DOWN, (l02 + 0.0) * ROUND_DOWN)
    return [(l01 + rest[0]) * ROUND_DOWN, (l02 + rest[1]) * ROUND_DOWN, (l12 + rest[2]) * ROUND_DOWN,
            (closed_all + rest[3]) * ROUND_DOWN]


def three_rest(c2: list) -> list:
    """c^2(V - S) rounded down for the rows of :func:`~tritools.solve.robust_enum.subset_masks` (3) (the pairs
    {0, 1}, {0, 2}, {1, 2}, then all views) from the squared thresholds ``c2`` (3 floats, > 0, inf allowed): the
    scalar twin of the masked sum (0 inside S) over the views in view order (numpy's order for three terms) times
    ``ROUND_DOWN``, bit for bit (tests/test_single_call_twins.py)."""
    c0, c1, c2_ = c2
    return [((0.0 + 0.0) + c2_) * ROUND_DOWN, ((0.0 + c1) + 0.0) * ROUND_DOWN, ((c0 + 0.0) + 0.0) * ROUND_DOWN,
            ((0.0 + 0.0) + 0.0) * ROUND_DOWN]


def exact_terms(c2) -> float:
    """The least of the exact terms of the sets of at most one view (c^2 of the others, rounded down): the scalar
    twin of those terms of :func:`~tritools.solve.robust_enum_run.lower_bounds` (each sum over the views in view
    order with 0 for the left-out view, numpy's order below 8 terms; the minimum), bit for bit
    (tests/test_single_call_twins.py).  ``c2`` a list or array of the squared thresholds (> 0, inf allowed); from 8
    views on (numpy's order then depends on the layout) lower_bounds itself."""
    c2 = [float(v) for v in c2]
    n = len(c2)
    if n >= 8:
        return float(lower_bounds(np.array([np.inf]), np.full((1, 1), np.inf), np.array(c2)[None])[0])
    small = []
    for i in range(n):
        t = 0.0 if i == 0 else c2[0]
        for j in range(1, n):
            t = t + (0.0 if j == i else c2[j])
        small.append(t)
    total = c2[0]
    for v in c2[1:]:
        total = total + v
    return min(min(small) * ROUND_DOWN, total * ROUND_DOWN)


def three_lower_bound(ub: float, terms: list, exact: float) -> float:
    """The scalar twin of :func:`~tritools.solve.robust_enum_run.lower_bounds` for one problem: the least of UB, the
    closed terms (:func:`three_terms`) and the exact terms (:func:`exact_terms`); NaN-free inputs (bounds and sums of
    squared thresholds), so the minimum of floats is numpy's."""
    return min(ub, min(terms), exact)
