"""Certified L2 lower bounds of view subsets, cached: the node bounds of the robust (TLS) search.

For a subset S of the views, L2*(S) = min_X sum_{i in S} d_i(X)^2 (pixels^2, d_i the distance from
Phi(X, P_i) to the region R_i) is bounded below by the project's certified L2 path on the sub-problem
(cameras and regions of S): L2*(S) >= 2 |S| gamma_LB(S)^2, valid under floating point whether or not the
sub-problem certified (every gamma_LB of :func:`tritools.triangulate` is a rigorous bound).  The product is
rounded downward (:data:`ROUND_DOWN`).  Facts used for free:

* |S| <= 1: L2*(S) = 0 (the projection of a point on the view's ray can sit anywhere in the region);
* monotonicity: S subset of T gives L2*(S) <= L2*(T), so a caller may take the max with any subset's bound;
* superadditivity: for disjoint S_1, ..., S_k inside S, L2*(S) >= sum_k L2*(S_k) (each term of the sum over
  S is a term of exactly one S_k, and each L2*(S_k) is a minimum over X).  :meth:`SubsetBounds.packing_bound`
  takes a greedy packing of the cached view pairs: a subset holding a wrong match w inherits the large
  L2*({w, v}) of its pairs, with no solve.

A search only needs a bound up to the level where it stops mattering (``SubsetBounds.enough``: the best TLS
value found plus the largest squared threshold -- a node bound saturates there, see
:mod:`tritools.solve.robust`).  So a subset the verification does not certify first gets its packing bound;
the batched degree-2 SDP runs only for those whose packing bound is below ``enough`` and that lie inside the
caller's ``hint`` (its best inlier set); the others keep the packing bound (``cheap``) until the caller
:meth:`SubsetBounds.reopen` s them, where that bound did not prune.

Point regions go through the vectorised verification path (:func:`tritools.solve.fastpath.verify_points`),
one numpy call per subset size; what it does not certify (and every other region type) through
:func:`tritools.triangulate` on the sub-problem, within the caller's deadline.  Every sub-problem also yields
an estimate X_S, which the search uses as a candidate for the TLS upper bound.
"""
from __future__ import annotations

import itertools
import math
import time
from collections import defaultdict

import numpy as np

from ..model.regions import Point
from ..result import Status
from .coplanar import (CEILING_MIN_VIEWS, COPLANAR_BUDGET_NAME, COPLANAR_MAX_CEILING, hopeless_subset,
                       plane_distances2, sits_on_ceiling, subset_futile)
from .fastpath import stack_point_problems, verify_checked
from .robust_subsolve import EXHAUSTED, ROUND_DOWN, TRUSTED_LOWER_BOUND, solve_subproblem
from .robust_verify import parent_frames, verify_in_parent
from .sdp_batch import solve_corollary1_points

__all__ = ["SubsetBounds", "compute_many", "ROUND_DOWN", "TRUSTED_LOWER_BOUND", "EXHAUSTED", "PACKING",
           "NODE_BUDGET_NAME"]

#: the cheap paths (pair packing bounds instead of SDPs, verification-only requests, and the search's
#: leave-one-out root bound, :meth:`tritools.solve.robust.TlsSearch.leave_one_out_bound`); False gives the plain
#: path (every subset the verification does not certify goes to the batched SDP), which the tests compare against.
PACKING = True
#: proper subsets of point problems are first verified in their parent's normalised frame
#: (:func:`tritools.solve.robust_verify.verify_in_parent`: no normalisation per subset); False gives the
#: per-subset path only (the tests compare the two).
IN_PARENT = True
#: triples tried by :meth:`SubsetBounds.split_bound` before a full-plan solve of a whole subset (0: none).
SPLIT_TRIES = 6
#: :meth:`SubsetBounds.strengthen` solves a weak subset (its delta = 2 bound known) with the degree plan from this
#: degree on: the verification and delta = 2 steps again cost 2-8x the delta = 4 step and decide nothing new.
FULL_FROM_DELTA = 4
#: time limit (seconds) of one sub-problem solved by :func:`tritools.triangulate` (capped by the caller's deadline)
SUB_TIME_LIMIT = 10.0
#: seconds per view that a sub-problem of regions spends before any step can stop at its deadline (the regions'
#: normalisation and the verification's set-up: ~0.25 + ~0.3 ms a view of mixed regions at 100 views, where a
#: 0.05 s call started its all-views sub-problem with 40 ms left and ended at 1.2-1.6x its limit); one with less
#: time left is not started (bound 0, weak).
SUB_REGION_SETUP_SECONDS = 5e-4
#: the name of the search's own node budget in a stopped search's message (other rules rename it:
#: :data:`tritools.solve.coplanar.COPLANAR_BUDGET_NAME`, :data:`tritools.solve.robust_cells.CELL_BUDGET_NAME`).
NODE_BUDGET_NAME = "node budget"


class SubsetBounds:
    """Cache of certified L2 lower bounds (pixels^2) and estimates per view subset (a ``frozenset``).

    ``bound(S)`` reads the cache; :meth:`compute` fills it for many subsets at once (batched by size for
    point regions).  ``estimates`` collects every (subset, X) produced, for the caller's upper bound;
    ``n_solved`` counts sub-problems solved."""

    def __init__(self, cameras: np.ndarray, regions, options, deadline, points=None):
        """``regions``, or None with ``points`` (N, 2): point regions by their centres (:attr:`regions` builds
        the Point objects when first asked)."""
        self.C = cameras
        self.opts = options
        self.deadline = deadline
        if regions is None:
            self._regions, self.points, self.x = None, True, np.asarray(points, float)
        else:
            self._regions = list(regions)
            self.points = all(r.is_point for r in self._regions)             # the regions say
            self.x = np.array([r.center for r in self._regions], float) if self.points else None
        self._lb: dict = {}
        self._X: dict = {}
        self.n_solved = 0
        self.weak: set = set()                 # subsets bounded by a light solve that did not certify
        #: subsets whose bound is the L2 path's last word (:mod:`tritools.solve.robust_futile`): the full degree plan
        #: ended not_certified, or no Corollary 1 degree can raise the bound (coplanar centres)
        self.exhausted: set = set()
        self.new_estimates: list = []          # (subset, X) produced since the caller last read them
        #: a lower bound at or above this value serves the caller as well as any larger one (module docstring)
        self.enough = math.inf
        self.c2 = None                         # the caller's squared thresholds (N,), for saturation()
        self._c2_list = None                   # c2 as floats (saturation's sums)
        self.defer: set = set()                # subsets to verify only: not certified -> left unknown, in unverified
        self.unverified: set = set()           # subsets the verification did not certify (not verified again)
        self.n_packed = 0                      # subsets bounded by their pair packing alone
        #: the caller's best inlier set: a subset of >= 3 views not inside it (it holds a view the best candidate
        #: calls an outlier) gets its pair packing bound only, no solve (``cheap``), until :meth:`reopen`
        self.hint = None
        self.cheap: set = set()
        self.retry: set = set()                # reopened subsets: the full treatment (verify, packing, SDP)
        self._floor: dict = {}                 # reopened subsets' packing bounds, kept by the next _store
        self._frame = None                     # the parent's normalised frame (robust_verify.ParentFrame), or False
        self.n_in_parent = 0                   # subsets bounded in the parent's frame
        self.budget_exceeded = False           # a sub-problem stopped at the memory budget (the caller's status)
        self.timed_out = False                 # a sub-problem stopped by its share of the time (review 38b M1)
        self.trial: dict = {}                  # subsets verified in the parent frame but not accepted: their
        #                                        polished estimate (a candidate only, no bound)
        self._plane_d2 = None                  # note_weak: dist(x_i, l_i)^2 of coplanar centres' lines, or False
        self.n_ceiling = 0                     # weak subsets whose bound sits on that ceiling (node_budget)
        self.on_ceiling: set = set()           # ... and which they are
        self.node_budget_name = NODE_BUDGET_NAME

    def frame(self):
        """The parent problem's :class:`tritools.solve.robust_verify.ParentFrame` (point regions; computed when first
        asked unless a batch set it), or None where the normalisation failed or the regions are not points."""
        if self._frame is None:
            self._frame = (parent_frames(self.C[None], self.x[None])[0] if self.points else None) or False
        return self._frame or None

    def set_frame(self, frame) -> None:
        self._frame = frame or False

    @property
    def regions(self) -> list:
        if self._regions is None:
            self._regions = [Point(p) for p in self.x]
        return self._regions

    def known(self, S: frozenset) -> bool:
        return len(S) <= 1 or S in self._lb

    def bound(self, S: frozenset) -> float:
        """The cached lower bound of L2*(S) (0 for |S| <= 1)."""
        return 0.0 if len(S) <= 1 else self._lb[S]

    def inherited(self, S: frozenset) -> float:
        """The largest cached bound of S and of its subsets (monotonicity: a lower bound of L2*(S)); 0 if none."""
        return max([0.0] + [v for T, v in self._lb.items() if T <= S])

    def estimate(self, S: frozenset):
        return self._X.get(S)

    def saturation(self, S: frozenset) -> float:
        """A bound of L2*(S) above this level serves the caller as well as any larger one: ``enough``, or the sum of
        the squared thresholds of S (``c2``, set by the caller) if lower (module docstring)."""
        if self.c2 is None:
            return self.enough
        if self._c2_list is None:
            self._c2_list = [float(v) for v in self.c2]
        return min(self.enough, sum(self._c2_list[i] for i in S))    # float sums overflow to inf, as they should

    def packing_bound(self, S: frozenset) -> float:
        """sum of the cached bounds of disjoint view pairs inside S, picked greedily by size (module docstring:
        superadditivity), rounded down; 0 when no pair of S is cached.  The pairs are those of S in the cache, found by
        whichever is shorter, S's pairs or the cache (|S| = 320 of 400 views: 51,040 pairs, ~15 ms past a deadline),
        taken by bound, ties in the order of their views."""
        if len(S) * (len(S) - 1) // 2 <= len(self._lb):
            pairs = [(self._lb[P], P) for P in map(frozenset, itertools.combinations(sorted(S), 2))
                     if P in self._lb and self._lb[P] > 0]
        else:
            pairs = [(b, P) for P, b in self._lb.items() if len(P) == 2 and b > 0 and P <= S]
        pairs.sort(key=lambda bp: (-bp[0], sorted(bp[1])))
        used, total = set(), 0.0
        for b, P in pairs:
            if not (P & used):
                total += b
                used |= P
        return total * ROUND_DOWN

    def node_budget(self, default: int) -> int:
        """The search's node budget: ``default``, or 0 (stop, :attr:`node_budget_name` says why) once
        :data:`~tritools.solve.coplanar.COPLANAR_MAX_CEILING` subsets got a delta = 2 bound that sits on the ceiling
        of coplanar centres (:func:`tritools.solve.coplanar.sits_on_ceiling`: no degree can raise them)."""
        if self.n_ceiling < COPLANAR_MAX_CEILING and not self._hint_on_ceiling():
            return default
        self.node_budget_name = COPLANAR_BUDGET_NAME
        return 0

    def _hint_on_ceiling(self) -> bool:
        """The caller's best inlier set (``hint``) has a bound on its ceiling s_pi clearly below the cost of its own
        estimate (:func:`tritools.solve.coplanar.hopeless_subset`): the leaf of the best candidate cannot be pruned,
        so no search over these bounds can certify."""
        if self.hint is None or self.hint not in self.on_ceiling or self.hint not in self._X:
            return False
        views = sorted(self.hint)
        return hopeless_subset(self.C[views], self.x[views], self._plane_d2[views], self._X[self.hint])

    def note_weak(self, S: frozenset) -> None:
        """Mark S weak (its delta = 2 bound, stored, did not certify) and count it when it sits on its ceiling."""
        self.weak.add(S)
        self._count_ceiling(S)

    def _coplanar(self) -> bool:
        """Whether the views' centres are coplanar (point regions, >= 4 views: three centres always are, and a
        3-view problem has the exact-variety step): ``_plane_d2`` holds dist(x_i, l_i)^2 then."""
        if self._plane_d2 is None:
            self._plane_d2 = (plane_distances2(self.C, self.x) if self.points else None) if len(self.C) > 3 else None
            self._plane_d2 = False if self._plane_d2 is None else self._plane_d2
        return self._plane_d2 is not False

    def _count_ceiling(self, S: frozenset) -> None:
        if self._coplanar() and len(S) >= CEILING_MIN_VIEWS and S not in self.on_ceiling \
                and sits_on_ceiling(self._lb[S], self._plane_d2[sorted(S)]):
            self.n_ceiling += 1
            self.on_ceiling.add(S)

    def compute(self, subsets) -> None:
        """Fill the cache for every subset not known yet (duplicates and |S| <= 1 skipped)."""
        compute_many([(self, subsets)])

    def strengthen(self, S: frozenset, need: float = math.inf, limit: float = SUB_TIME_LIMIT) -> bool:
        """A better bound of S when its bound came from a light (delta = 2) solve that did not certify; True when
        the bound may have changed.  First by superadditivity over a split (:meth:`split_bound`), which stops once
        it reaches ``need`` (the level the caller's node must reach); else by solving S with the full degree plan,
        which stops once its rigorous bound reaches ``need`` (:mod:`~tritools.solve.robust_subsolve`; S stays weak)."""
        if S not in self.weak or self.deadline.expired:
            return False
        self.weak.discard(S)
        old = self._lb[S]
        split = self.split_bound(S, need)
        if split >= need:
            self._lb[S] = max(old, split)
            return True
        views = sorted(S)                 # coplanar centres: no Corollary 1 degree can certify (solve.coplanar)
        if subset_futile(self.C[views], [self.regions[i] for i in views], self.opts, old, self._X.get(S)):
            self._lb[S] = max(old, split)
            self.exhausted.add(S)
            return split > old
        self._lb.pop(S)
        # a batched SDP that handed S back left no delta = 2 bound: with coplanar centres the plan from delta = 2,
        # whose ceiling rule (solve.coplanar.futile_after) stops it there, instead of the delta = 4 step
        fresh = old <= 0.0 and self._coplanar()
        self._solve_one(S, light=False, from_delta=None if fresh else FULL_FROM_DELTA, limit=limit, need=need)
        self._lb[S] = max(self._lb[S], old, split)
        self._count_ceiling(S)
        return True

    def solve_full(self, S: frozenset, need: float, X=None) -> tuple:
        """(L2 lower bound of S in pixels^2, rounded down -- 0 without one --, its estimate or None) by the degree
        plan from :data:`FULL_FROM_DELTA` (three views: Theorem 1 at delta = 4 first,
        :mod:`~tritools.solve.robust_subsolve`), stopping once its rigorous bound reaches ``need``: the
        enumeration's last open set, whose degree-2 bounds fall short
        (:meth:`tritools.solve.robust_enum_run._Group._solve_all`).  Not cached: a search that runs after it bounds S
        its own way (a stopped or exhausted plan from delta = 4 stored here kept a two-view search from its
        verification, which certified).  No solve past the deadline or where no Corollary 1 degree can certify S
        (:func:`~tritools.solve.coplanar.subset_futile` at its candidate ``X``, a world point, or None)."""
        views = sorted(S)
        if self.deadline.expired or subset_futile(self.C[views], [self.regions[i] for i in views], self.opts, 0.0, X):
            return 0.0, None
        out = self._solved(views, False, FULL_FROM_DELTA, SUB_TIME_LIMIT, need)
        return (0.0, None) if out is None else (max(out.lb, 0.0), out.X)

    def split_bound(self, S: frozenset, need: float) -> float:
        """max over tried triples T of S holding a view outside the caller's ``hint`` (a likely wrong match w) of
        L2LB(T) + L2LB(S - T), rounded down: L2*(S) >= L2*(T) + L2*(S - T) (superadditivity, module docstring).
        A triple's L2 problem is solved in full (:meth:`_full_bound`, typically 1-200 ms against seconds for a
        whole problem with a wrong match); the rest's bound is its cached one, a full solve of up to 3 views, or its
        pair packing.  At most :data:`SPLIT_TRIES` triples, the views paired with w by the largest cached pair
        bounds first; stops at ``need``.  0 when S has fewer than 4 views or no suspect."""
        if len(S) < 4 or self.hint is None or SPLIT_TRIES <= 0:
            return 0.0
        best, tried = 0.0, 0
        for w in sorted(S - self.hint):
            pair = {v: self._lb.get(frozenset((w, v)), 0.0) for v in S if v != w}
            others = sorted(pair, key=lambda v: -pair[v])
            for a, b in itertools.combinations(others, 2):
                if tried >= SPLIT_TRIES or self.deadline.expired:
                    return best
                tried += 1
                T = frozenset((w, a, b))
                R = S - T
                rest = self._full_bound(R) if len(R) <= 3 else self._lb.get(R, self.packing_bound(R))
                best = max(best, (self._full_bound(T) + rest) * ROUND_DOWN)
                if best >= need:
                    return best
        return best

    def _full_bound(self, T: frozenset) -> float:
        """The bound of T, solved with the full degree plan unless cached from a solve that was not light (a weak
        or packing-only bound is solved again; |T| <= 1: 0)."""
        if len(T) <= 1:
            return 0.0
        if T in self._lb and T not in self.weak and T not in self.cheap:
            return self._lb[T]
        old = self._lb.pop(T, 0.0)
        weak = T in self.weak                      # its delta = 2 bound is known: the plan from FULL_FROM_DELTA
        self.weak.discard(T)
        self.cheap.discard(T)
        self._solve_one(T, light=False, from_delta=FULL_FROM_DELTA if weak else None)
        self._lb[T] = max(self._lb[T], old)
        return self._lb[T]

    def reopen(self, S: frozenset) -> bool:
        """Forget the packing-only bound of S (in ``cheap``) so that the next request gives it the full treatment;
        False when S has none."""
        if S not in self.cheap:
            return False
        self.cheap.discard(S)
        self._floor[S] = self._lb.pop(S, 0.0)      # still a valid bound: the new one is never lower
        self.retry.add(S)
        return True

    def _solve_one(self, S: frozenset, light: bool = True, from_delta: int | None = None,
                   limit: float = SUB_TIME_LIMIT, need: float = math.inf) -> None:
        """One sub-problem through :func:`tritools.solve.robust_subsolve.solve_subproblem`: with ``light`` only its
        degree-2 steps (:meth:`strengthen` runs the full plan where the search needs it), ``from_delta`` the plan's
        first degree, ``need`` the level the caller's node needs (the full plan stops there: S stays weak, never
        exhausted).  ``limit``: seconds (capped by the deadline; :data:`SUB_TIME_LIMIT` by default, inf: the
        deadline alone)."""
        views = sorted(S)
        remaining = self.deadline.remaining()
        if not self.points and remaining is not None and remaining < len(views) * SUB_REGION_SETUP_SECONDS:
            self.weak.add(S)                    # no time for its set-up: 0 is a valid bound, not a final one
            self._store(S, 0.0, None)
            return
        out = self._solved(views, light, from_delta, limit, need)
        if out is None:
            self._store(S, 0.0, None)           # e.g. coincident or duplicated cameras: 0 is a valid bound
            return
        self._keep(S, out)

    def seed(self, S: frozenset, out) -> None:
        """S's bound from a :class:`~tritools.solve.robust_subsolve.SubSolve` solved elsewhere (the single call's L2
        pass, :mod:`tritools.solve.robust_settle`), kept as :meth:`_solve_one` keeps its own."""
        self.n_solved += 1
        self._keep(S, out)

    def _keep(self, S: frozenset, out) -> None:
        """A solved sub-problem's outcome into the cache: weak, exhausted, its bound and estimate."""
        if (out.light or out.stopped) and not out.certified:     # light as it ran (the options may refuse it)
            self.weak.add(S)
        if out.exhausted:                       # the plan ran out, not at a time or memory limit nor at ``need``
            self.exhausted.add(S)
        self._store(S, out.lb, out.X)

    def _solved(self, views: list, light: bool, from_delta, limit: float, need: float):
        """:func:`~tritools.solve.robust_subsolve.solve_subproblem` of the sub-problem of ``views`` within ``limit``
        seconds and the deadline, counted (``n_solved``, ``budget_exceeded``); None where the input is refused."""
        remaining = self.deadline.remaining()
        limit = limit if remaining is None else min(limit, remaining)      # inf, no deadline: the options' budget
        out = solve_subproblem(self.C[views], [self.regions[i] for i in views], self.opts, light=light,
                               from_delta=from_delta, limit=limit, need=need, points=self.points)
        if out is not None:
            self.n_solved += 1
            self.budget_exceeded |= out.budget_exceeded
            self.timed_out |= out.timed_out
        return out

    def _store(self, S: frozenset, lb: float, X) -> None:
        self._lb[S] = max(lb, 0.0, self._floor.pop(S, 0.0))
        if X is not None and np.all(np.isfinite(X)):
            X = np.asarray(X, float)
            self._X[S] = X
            self.new_estimates.append((S, X))

    def take_estimates(self) -> list:
        out, self.new_estimates = self.new_estimates, []
        return out


def compute_many(requests) -> dict:
    """Fill the caches of several :class:`SubsetBounds` (``requests``: (cache, subsets) pairs) at once: point
    sub-problems of equal size, from every cache, in one vectorised verification call; what it does not certify
    gets its pair packing bound (:meth:`SubsetBounds.packing_bound`) when that reaches the cache's ``enough``,
    else one batched SDP call (what that hands back too is bounded by 0 for now and marked weak); other regions
    one by one through :func:`tritools.triangulate`.  A subset in a cache's ``defer`` set is only verified: not
    certified, it is left unknown (and not verified again).  Returns id(cache) -> seconds of the sub-problems solved
    one by one for it (the drive charges them to their own search, :func:`tritools.solve.robust_drive.charges`)."""
    groups, single = defaultdict(list), []
    for sb, subsets in requests:
        for S in dict.fromkeys(subsets):
            if not sb.known(S):
                if sb.points:
                    groups[(len(S), id(sb.opts))].append((sb, S))
                else:
                    single.append((sb, S))
    for key in sorted(groups, key=lambda k: k[0]):
        items = groups[key]
        fresh = [(sb, S) for sb, S in items if S not in sb.unverified]
        verified = []                           # verified in their parent's frame: not again below
        if IN_PARENT and fresh:
            fresh, verified = _in_parent(fresh)
        deadline = _earliest([sb.deadline for sb, _ in items])
        left = (_batch(fresh, lambda C, x, opts: _verify_stack(C, x, opts, deadline)) if fresh else []) + verified + \
            [(sb, S) for sb, S in items if S in sb.unverified]
        left = _expired(left)                  # the items whose own search's deadline has passed: 0, nothing more
        if PACKING:
            left = _hinted(_packed(_deferred(left)))
        if left and key[0] <= SDP_STACK_MAX_VIEWS:
            left = _batch(left, lambda C, x, opts: _sdp_stack(C, x, opts, deadline))
        for sb, S in left:                      # handed back by both batches (typically subsets with outliers):
            sb._store(S, 0.0, None)             # 0 for now (the caller keeps its inherited bounds);
            sb.weak.add(S)                      # strengthen() solves them one by one where the search needs it
    solved: dict = defaultdict(float)
    for sb, S in single:
        if sb.deadline.expired:
            sb._store(S, 0.0, None)             # 0 is a valid bound; the search reports the time limit
        else:
            t = time.monotonic()
            sb._solve_one(S)
            solved[id(sb)] += time.monotonic() - t
    return solved


def _expired(items: list) -> list:
    """Settle the items whose cache's deadline has passed: the bound 0 (valid; the search then stops with its time
    limit), deferred ones (verification only) left unknown as :func:`_deferred` leaves them -- no pair packing bound
    (O(|S|^2) per subset: 80,000 pair look-ups, ~10 ms, for a 400-view subset; seconds for a few hundred) and no
    SDP after the deadline; the other items."""
    left = []
    for sb, S in items:
        if not sb.deadline.expired:
            left.append((sb, S))
            continue
        sb.unverified.add(S)
        if S in sb.defer:
            sb.defer.discard(S)
        else:
            sb._store(S, 0.0, None)
            sb.weak.add(S)
    return left


def _earliest(deadlines: list):
    """The earliest of the searches' deadlines (one vectorised verification serves them all), None without any."""
    ends = [d.end for d in deadlines if d is not None and d.end is not None]
    return type(deadlines[0])(min(ends)) if ends else None


def _in_parent(items: list) -> tuple:
    """Store the bounds of the subsets that :func:`tritools.solve.robust_verify.verify_in_parent` accepts
    (equal-size point subsets, verified in their parent's normalised frame, one vectorised call, the whole
    problem included); (the subsets without a frame, left for the per-subset verification; the subsets verified
    here but not accepted, which go on to the packing bound / SDP: a second verification in their own frame
    decided none of 94 such triples in benchmarks/robust_speed.py, at the cost of a normalisation each)."""
    use, rest = [], []
    for sb, S in items:
        (use if sb.frame() is not None else rest).append((sb, S))
    deadline = _earliest([sb.deadline for sb, _ in use])
    if not use or (deadline is not None and deadline.expired):   # past it: verified, none accepted (no O(M) work)
        return rest, use
    estimates = [[] if len(S) < 3 else list(itertools.islice((sb._X[T] for T in (S - {v} for v in S) if T in sb._X),
                                                            2)) for sb, S in use]
    enough = np.array([sb.saturation(S) for sb, S in use])
    try:
        good, lb, X = verify_in_parent([sb.C for sb, _ in use], [sb.frame() for sb, _ in use],
                                       [np.array(sorted(S)) for _, S in use], estimates, use[0][0].opts.tolerances,
                                       enough, deadline)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return items, []
    verified = []
    finite = np.isfinite(X).all(axis=1)             # (a subset past the deadline has none: O(1) per item then)
    for k, (sb, S) in enumerate(use):
        if good[k]:
            sb._store(S, float(lb[k]), X[k])
            sb.n_solved += 1
            sb.n_in_parent += 1
        else:
            verified.append((sb, S))
            if finite[k]:
                sb.trial[S] = X[k]
    return rest, verified


def _hinted(items: list) -> list:
    """Store the packing bound of the subsets of >= 3 views outside their cache's ``hint`` (in ``cheap``): the
    verification did not certify them, and a subset holding a likely outlier needs a large bound, rarely a
    tight one (the batched SDP costs ~10-100x the verification and often decides nothing there); the rest.
    Once a cache's deadline has passed no more packing bounds for it (O(|S|^2) each): its items are returned."""
    left = []
    for sb, S in items:
        if sb.deadline.expired:
            left.append((sb, S))
        elif sb.hint is not None and len(S) >= 3 and S not in sb.retry and not S <= sb.hint:
            sb._store(S, sb.packing_bound(S), None)
            sb.cheap.add(S)
            sb.n_packed += 1
        else:
            left.append((sb, S))
    return left


def _deferred(items: list) -> list:
    """The items not deferred; the deferred ones (verification only) are marked unverified and left unknown."""
    left = []
    for sb, S in items:
        sb.unverified.add(S)
        if S in sb.defer:
            sb.defer.discard(S)
        else:
            left.append((sb, S))
    return left


def _packed(items: list) -> list:
    """Store the packing bound of the items where it reaches their cache's ``enough``; the rest.  Once a cache's
    deadline has passed no more packing bounds for it (O(|S|^2) each, :func:`_expired`)."""
    left = []
    for sb, S in items:
        level = sb.saturation(S)
        b = sb.packing_bound(S) if math.isfinite(level) and not sb.deadline.expired else 0.0
        if b > level:
            sb._store(S, b, None)
            sb.n_packed += 1
        else:
            left.append((sb, S))
    return left


def _verify_stack(C, x, opts, deadline=None):
    """(decided (M,), gamma_lb, X, certified (M,)) of the vectorised verification: certified problems only.  By
    the stacked code however many sub-problems the round has (a search's numbers then do not depend on the other
    searches of its batch, review 19 F4)."""
    C, x, good = stack_point_problems(C, x, "verify_points")
    b = verify_checked(C, x, good, opts.tolerances, deadline=deadline, scalar=False)
    ok = b.certified & np.isfinite(b.gamma_lb)
    return ok, b.gamma_lb, b.X, ok


def _sdp_stack(C, x, opts, deadline=None):
    """(decided, gamma_lb, X, certified) of the batched Corollary 1, delta = 2 SDP
    (:func:`tritools.solve.sdp_batch.solve_corollary1_points`): its rigorous lower bound wherever it decided the
    problem, certified or not (an uncertified one is marked weak: :meth:`SubsetBounds.strengthen` may solve it
    with the full degree plan where the search needs it)."""
    b = solve_corollary1_points(C, x, tolerances=opts.tolerances, refine=opts.refine, deadline=deadline,
                                scalar=False)
    kernel = _kernel_hand_backs(b)
    X = np.where(kernel[:, None], np.nan, b.X)          # no estimate from a point the extraction did not give
    return (b.done | kernel) & np.isfinite(b.gamma_lb), b.gamma_lb, X, b.optimal & b.done


#: the largest subsets (views) sent to the batched dense Corollary 1 SDP (its structure and program grow ~N^4: 1.3 s
#: at 30 views, minutes at 140, review 8 F1); larger ones keep the bound 0, marked weak, for
#: :meth:`SubsetBounds.strengthen` (the full degree plan, which takes the sparse formulations at that size)
SDP_STACK_MAX_VIEWS = 32

#: the reason :func:`tritools.solve.sdp_batch.solve_corollary1_points` gives when only its point extraction failed
KERNEL_HAND_BACK = "Gram kernel of dimension"


def _kernel_hand_backs(b) -> np.ndarray:
    """The rows of an :class:`tritools.solve.sdp_batch.SdpBatch` handed back only because the Gram kernel is not
    one-dimensional (no point to extract): their lower bound is still rigorous -- the margin of
    :func:`sospoly.analysis.rigor` holds for any Gram matrix and any upper bound c_ub >= f*, and c_ub there is
    the cost at an actual (extracted or fallback) point -- and a TLS search needs the bound, not the point.
    Only rows whose decision is not a contradiction (NOT_CERTIFIED or OPTIMAL) count."""
    fine = {Status.NOT_CERTIFIED.value, Status.OPTIMAL.value}
    return np.array([not d and r.startswith(KERNEL_HAND_BACK) and st in fine
                     for d, r, st in zip(b.done, b.reason, b.status)], bool)


def _batch(items: list, step) -> list:
    """Run ``step`` on the stacked equal-size point sub-problems of ``items`` ((cache, subset) pairs); store what
    it decided, return the rest."""
    C = np.stack([sb.C[sorted(S)] for sb, S in items])
    x = np.stack([sb.x[sorted(S)] for sb, S in items])
    try:
        decided, gamma_lb, X, certified = step(C, x, items[0][0].opts)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return items
    n = C.shape[1]
    left = []
    for k, (sb, S) in enumerate(items):
        if decided[k]:
            sb._store(S, 2 * n * float(gamma_lb[k]) ** 2 * ROUND_DOWN, X[k])
            sb.n_solved += 1
            if not certified[k]:            # a valid but loose delta = 2 bound: strengthen() may redo it
                sb.note_weak(S)
        else:
            left.append((sb, S))
    return left
