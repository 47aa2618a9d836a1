"""Certified outlier-robust triangulation: truncated least squares (TLS) by branch and bound over inlier sets.

The problem.  For thresholds c_i > 0 (pixels, the caller's image units; ``inf`` = always an inlier) and the
distances d_i(X) = d(Phi(X, P_i), R_i) of the L2 problem (SPEC §1, any region type),

    f_TLS(X) = sum_i min(d_i(X)^2, c_i^2),     gamma_TLS(X) = sqrt(f_TLS(X) / (2N)),

in the units of gamma (with every c_i infinite it is the L2 problem exactly).  The reported inlier set of X
is {i : d_i(X) < c_i}.

The identity.  Writing T(X) = {i : d_i(X) < c_i},

    min_X f_TLS(X) = min over subsets S of [ L2*(S) + sum_{i not in S} c_i^2 ],   L2*(S) = min_X sum_{i in S} d_i^2,

so a certificate for TLS is a certificate over inlier sets whose pieces are the project's certified L2
lower bounds of sub-problems (:mod:`tritools.solve.robust_bounds`: L2*(S) >= 2|S| gamma_LB(S)^2, rigorous
under floating point for every region type; L2*(S) = 0 for |S| <= 1).

The branch and bound.  A node fixes I (inliers), O (outliers) and leaves U undecided; it holds the X with
I subset of T(X) and O disjoint from T(X).  For such X, with s = sum_{i in I} d_i(X)^2,

    f_TLS(X) = c^2(O) + s + sum_{u in U} min(c_u^2, d_u(X)^2),
    L2*(I) <= s <= sum_{i in I} c_i^2,      d_u(X)^2 >= L2*(I + {u}) - s,

and an X that beats the best value UB found has s <= UB - c^2(O).  Hence the node bound

    LB(node) = min( UB, c^2(O) + min_{s in [L2LB(I), min(c^2(I), UB - c^2(O))]}
                                   [ s + sum_{u in U} min(c_u^2, max(0, a_u - s)) ] ),
    a_u = max(L2LB(I), L2LB(I + {u})),

a piecewise-linear minimum in s attained at the interval's ends or at a breakpoint a_u or a_u - c_u^2
(:func:`lookahead_bound`).  At the root, every X with T(X) != all views pays at least min_i c_i^2, so
f_TLS* >= min(L2LB(all), min_i c_i^2): tracks without outliers are certified by their L2 certificate alone.
One level down (:meth:`TlsSearch.leave_one_out_bound`), an X with an outlier j pays c_j^2 plus the root bound
of the problem without j, so f_TLS* >= min(L2LB(V), min_j [c_j^2 + min(L2LB(V - j), min_{i != j} c_i^2)]):
a clean track whose L2 optimum costs more than min c^2 is certified from its N leave-one-out sets (their bounds
from two halves first, :mod:`tritools.solve.robust_loo`).  A track with up to three wrong matches O is first tried
by the cover f_TLS* >= min(min_{j in O} LB(node {j}), c^2(O) + TLS*(V - O)) (:mod:`tritools.solve.robust_suspects`,
valid for any O), from the pairs holding O and V - O's own bounds, before the pairs and the search; after the
candidate stage the same cover is taken with O the best candidate's outliers, of any number, and V - O bounded by
the group bound (:mod:`tritools.solve.robust_loo`: every outlier of V - O charged).  The search stops early when a
leaf's bound is exhausted below UB (:mod:`tritools.solve.robust_futile`: certification out of reach).  Before the
search over inlier sets, point problems try the branch and bound over cells of candidate points
(:mod:`tritools.solve.robust_cells`: patterns of the first two inliers, a second-order bound per cell), which closes
where thresholds of 2-3 sigma leave many near-optimal inlier sets.

Search: an upper bound first -- the full L2 estimate, the L2 estimate of every view pair (at most
:data:`MAX_PAIRS`, sampled beyond) and local optimisation from the best few (inlier set -> L2 estimate
of the set -> inlier set, :data:`LO_ROUNDS` rounds); every sub-problem solved on the way offers its
estimate too.  Then depth first, views in :func:`branching_order` (confident inliers, then views near their
threshold), the "inlier" child first.  Sub-bounds are inherited (a subset's bound holds for every superset:
the parent's L2*(I + {u}), the pairs, the triples with two anchor views) and computed only where the
inherited bound does not prune -- never on the path of the best candidate, whose nodes cannot be pruned
before their leaf.  A node is pruned when its bound meets UB under the certificate rule; the reported lower
bound is the minimum of UB and of the bounds of every node pruned below UB or left open (a node budget
:data:`MAX_NODES` or the time limit stops the search with valid bounds, certified if they meet anyway).

The search is a generator: it yields the subsets whose bounds it needs, and :func:`drive` computes those of
many searches together, one vectorised call per subset size (:func:`tritools.solve.robust_bounds.compute_many`).

Units and the decision.  The certificate rule of :class:`sospoly.Tolerances` (``certified`` /
``contradicts`` / ``consistent``) is applied to f_TLS in pixels^2 at the problem's own scale
``min(min_i c_i^2, rho^2)`` (the smallest finite squared threshold, capped by the squared residual scale rho
of the L2 normalisation, :func:`decision_scale`): the absolute part allows ``gap_abs`` times that scale,
the relative part ``gap_rel * max(scale, UB)``.  Bounds are reported as gamma = sqrt(f / 2N).
"""
from __future__ import annotations

import logging
import math
import time

import numpy as np

from ..model.cameras import as_world_frame, depth_rows
from ..model.frame import WorldFrame, world_frame
from ..model.normalize import normalization_for
from ..result import Attempt, Status, TriangulationResult
from .decide import cheirality
from .report import PointReport, point_report
from .trivial import local_estimate
from . import robust_bounds, robust_cells, robust_front, robust_futile, robust_suspects
from .robust_bounds import ROUND_DOWN, SubsetBounds
from .robust_drive import drive
from .settings import call_deadline
from .robust_loo import leave_one_out
from .robust_nodes import NodeBounds, lookahead_bound
from .robust_rays import centre_pair_candidates, ray_candidates, sampled_pairs
from .robust_costs import (MIN_THRESHOLD, decision_scale, disc_distances2, disc_shapes, point_distances2,  # noqa: F401
                           point_distances2_one, robust_thresholds, scale_from, tls_cost)
from .robust_report import tls_reported
from .stages.outcome import behind_message

__all__ = ["robust_thresholds", "triangulate_robust", "drive", "lookahead_bound", "tls_cost", "point_distances2",
           "MAX_NODES", "MAX_PAIRS", "MIN_THRESHOLD", "LO_ROUNDS", "TlsSearch"]

log = logging.getLogger(__name__)

#: the search stops (status not_certified, valid bounds) after this many nodes.
MAX_NODES = 4000
#: view pairs whose L2 estimates seed the upper bound (all pairs up to this many; a random sample beyond).
MAX_PAIRS = 500
#: rounds of local optimisation (inlier set -> L2 estimate -> inlier set) from each of the best pair candidates.
LO_ROUNDS = 5
#: local optimisation starts from this many of the best pair candidates.
LO_STARTS = 3
#: candidate-view pairs per block of :meth:`TlsSearch.screen` (the deadline is checked between blocks; ~5 ms each)
SCREEN_BLOCK = 1 << 16
#: candidate-view pairs that a screen starting past the deadline evaluates (:meth:`TlsSearch.screen`)
SCREEN_LATE = 1 << 12
#: candidates whose exact residuals (regions other than points and discs) a search keeps (then it starts afresh)
RESIDUAL_MEMO = 256
#: branching order (:func:`branching_order`): this many confident inliers first, then the views whose d_i / c_i is
#: within a factor AMBIGUOUS of 1.
ANCHORS = 2
AMBIGUOUS = 2.0
def branching_order(ratio: np.ndarray) -> np.ndarray:
    """The views in branching order from r_i = d_i / c_i at the best candidate: the :data:`ANCHORS` most
    confident inliers first (the lookahead needs inliers in I), then the ambiguous views (1/AMBIGUOUS < r_i <
    AMBIGUOUS, closest to the threshold first: deciding them early keeps the rest of the tree a chain), then
    the rest by r_i."""
    r = np.where(np.isfinite(ratio), ratio, np.inf)
    by_r = np.argsort(r, kind="stable")
    head = [int(i) for i in by_r[:ANCHORS] if r[i] < 1]
    rest = [int(i) for i in by_r if int(i) not in head]
    amb = sorted((i for i in rest if 1 / AMBIGUOUS < r[i] < AMBIGUOUS), key=lambda i: abs(math.log(r[i])))
    return np.array(head + amb + [i for i in rest if i not in amb], dtype=int)


class TlsSearch(NodeBounds):
    """One TLS problem: thresholds, the subset bounds, the best candidate, the branch and bound."""

    def __init__(self, cams, regions, c, opts, t0, points=None, origin=None):
        """``regions`` (a sequence of regions), or None with ``points`` (N, 2): point regions given by their
        centres (a batch of validated point problems; the Point objects are built only if a path needs them).

        The search runs in the world frame of :mod:`tritools.model.frame` (``origin``: its origin when the caller
        computed it for a stack, :func:`tritools.model.frame.world_origins`): in a georeferenced world (centres
        1e6-1e8 from the origin) its plain arithmetic would drift by 1e-7..1e-3 of the cost and the report's drift
        test withhold the certificate.  ``C`` are the cameras in that frame, ``C_user`` the caller's: the result
        (X, gamma_UB, residuals, depths, inliers) is reported on these, at the point moved back (:meth:`result`)."""
        self.C_user = cams
        self.frame = world_frame(cams) if origin is None else WorldFrame(np.asarray(origin, float))
        if self.frame.moved:
            cams = self.frame.cameras(cams)
        self.C, self.c, self.opts, self.t0 = cams, c, opts, t0
        self._regions, self.enum_terms = (None if regions is None else list(regions)), None   # enum_terms: robust_three
        self.N = len(regions) if regions is not None else len(points)
        with np.errstate(over="ignore"):
            self.c2 = c * c                              # c above 1e154: c^2 = inf (no threshold in floats)
        self.c2_max = float(np.max(self.c2))
        self.deadline = opts.budget.deadline()
        self.bounds = SubsetBounds(cams, regions, opts, self.deadline, points=points)
        self.bounds.c2 = self.c2
        self._scale = None                               # decision_scale, computed when first needed
        self._norm = None                                # its normalisation (also the fallback estimate's)
        self._resolved = None                            # the report's gamma resolution (:attr:`resolved`)
        self.tol = opts.tolerances
        self.best_X, self.best_f, self.best_S = None, math.inf, frozenset()
        self.cells_decided = False              # the certificate rests on the compensated cells (run)
        self.points = self.bounds.points
        self.x = self.bounds.x
        self.nodes = 0
        self.anchors, self.anchor_a = None, None     # see anchor_bounds
        self.loo_lb = 0.0                            # leave_one_out / suspect bound (candidates), where computed
        self._absC2 = None                           # |third rows| of the cameras (point_distances2_one)
        self._discs = None                           # (centres, radii) of disc regions, or False (screen)
        self._memo = {}                              # residuals of other regions' candidates (X bytes -> d)
        self.drows = None                           # depth rows of the cameras (report; a batch sets them)
        self.futile_leaf = None                     # (inlier set, its leaf bound) that fired the rule
        self.max_nodes = MAX_NODES                  # the search's node budget (smaller after an exhausted cell search)
        self.covered = set()                        # suspect sets O whose cover bound was taken (robust_suspects)
        self.cover_splits, self.cover_keys = {}, {}  # suspect set O -> its cover's split, its nodes' bound (_told)

    @property
    def regions(self) -> list:
        return self.bounds.regions

    def set_deadline(self, deadline) -> None:
        """The search's deadline, also its sub-bounds' (:func:`drive` moves it on in a batch)."""
        self.deadline = self.bounds.deadline = deadline

    @property
    def scale(self) -> float:
        """The scale of the certificate rule (:func:`decision_scale`)."""
        if self._scale is None:
            self._scale = scale_from(self.normalization().scale, self.c2)     # (decision_scale's value)
        return self._scale

    def normalization(self):
        """The L2 normalisation of the problem (:func:`~tritools.model.normalize.normalization_for`), computed once."""
        if self._norm is None:
            self._norm = normalization_for(self.C, self.regions)
        return self._norm

    def set_normalization_scale(self, s: float) -> None:
        """Give the L2 normalisation's image scale s of this problem, computed in a batch (:func:`scale_from`)."""
        self._scale = scale_from(s, self.c2)

    # ------------------------------------------------------------------ costs and the upper bound
    def residuals(self, X) -> np.ndarray:
        """d_i(X) (N,), inf where the projection is undefined: :func:`point_distances2` for point regions (the
        vectorised twin of :func:`tritools.solve.report.point_report`), :func:`disc_distances2` for discs, else
        point_report (the reported numbers always come from point_report, :meth:`report`)."""
        if self.points:
            return np.sqrt(self.sq_distances(X))
        if self.discs():
            return np.sqrt(disc_distances2(self.C, *self.discs(), np.asarray(X, float)[None])[0])
        key = np.asarray(X, float).tobytes()          # the same candidate is screened, offered, ordered: once
        if key not in self._memo:
            rep = point_report(X, self.C, self.regions, self.opts.world_frame)
            self._memo = self._memo if len(self._memo) < RESIDUAL_MEMO else {}
            self._memo[key] = np.full(self.N, np.inf) if rep.residuals is None else rep.residuals
            self._memo[key].setflags(write=False)
        return self._memo[key]

    def sq_distances(self, X) -> np.ndarray:
        """d_i(X)^2 (N,) of point regions (:func:`tritools.solve.robust_costs.point_distances2_one`)."""
        if self._absC2 is None:
            self._absC2 = np.abs(self.C[:, 2])
        return point_distances2_one(self.C, self._absC2, self.x, X)

    def screen(self, Xs: np.ndarray) -> np.ndarray:
        """f_TLS of many candidates (M, 3), only for ranking: vectorised for point and disc regions
        (:func:`tritools.solve.robust_costs.disc_distances2`) in blocks of :data:`SCREEN_BLOCK` candidate-views, else
        one by one; the first block always, the rest until the deadline (the candidates not reached rank last, inf:
        the ray candidates of a 400-view track, ~5,000 x 400, ran 0.3 s past a limit in one call; an M x N loop of
        exact distances, seconds).  A screen that starts past the deadline takes one block of :data:`SCREEN_LATE`
        candidate-views (a full first block, ~5 ms at 400 views, was 10% of a 0.05 s limit)."""
        f = np.full(len(Xs), np.inf)
        if not (self.points or self.discs()):
            for k, X in enumerate(Xs):
                if k and self.deadline.expired:
                    break
                f[k] = tls_cost(self.residuals(X), self.c)
            return f
        step = max(1, (SCREEN_LATE if self.deadline.expired else SCREEN_BLOCK) // self.N)
        for k in range(0, len(Xs), step):
            if k and self.deadline.expired:
                break
            d2 = point_distances2(self.C, self.x, Xs[k:k + step]) if self.points else \
                disc_distances2(self.C, *self.discs(), Xs[k:k + step])
            f[k:k + step] = np.sum(np.minimum(d2, self.c2[None]), axis=1)
        return f

    def discs(self) -> tuple | None:
        """(centres, radii) when every region is a disc or a point (:func:`disc_shapes`), else None; computed once."""
        if self._discs is None:
            self._discs = disc_shapes(self.regions) or False
        return self._discs or None

    def report(self, X) -> PointReport:
        """Residuals and depths of X in the caller's frame (X a user point; the caller's cameras ``C_user``):
        point_report for other regions; for point regions only the depths (the reported residuals are
        :func:`tritools.solve.robust_report.tls_reported`'s, from compensated projections on ``C_user``)."""
        if not self.points:
            return point_report(X, self.C_user, self.regions, self.opts.world_frame)
        if self.drows is None:                          # depth = h row_i . X~ (depths_stack's rows), once
            self.drows = depth_rows(self.C_user)
        Xh = np.array([X[0], X[1], X[2], 1.0], float)
        with np.errstate(over="ignore", invalid="ignore"):
            depths = as_world_frame(self.opts.world_frame).sign * (self.drows @ Xh)
        return PointReport(None, None, depths)

    def offer(self, X, d2=None) -> None:
        """A candidate: kept when its exact f_TLS (:func:`tritools.solve.report.point_report` distances) is
        lower than the best by more than round-off (ties keep the earlier one: the full L2 estimate first).  ``d2``:
        its :meth:`sq_distances`, where a stack computed them (:func:`~.robust_costs.point_distances2_rows`)."""
        if X is None or not np.all(np.isfinite(X)):
            return
        d, f = self.cost(X, d2)
        if f < self.best_f * (1 - 1e-12) or (self.best_X is None and np.isfinite(f)):
            self.best_X, self.best_f = np.asarray(X, float), f
            self.best_S = frozenset(int(i) for i in np.nonzero(d < self.c)[0])

    def cost(self, X, d2=None) -> tuple:
        """(d_i(X) (N,), f_TLS(X)) of a candidate X, exactly: :meth:`sq_distances` (or ``d2``) for point regions,
        tls_cost from the squared distances (inf: c^2); :meth:`residuals` for other regions."""
        if self.points:
            d2 = self.sq_distances(X) if d2 is None else d2
            return np.sqrt(d2), float(np.minimum(d2, self.c2).sum())
        d = self.residuals(X)
        return d, tls_cost(d, self.c)

    def fallback_estimate(self):
        """The local L2 estimate of every view (:func:`tritools.solve.trivial.local_estimate`, in the normalised
        frame), or None: the estimate of last resort, so that a search stopped before any candidate still
        reports X and gamma_UB.  Past the deadline the frame's origin (the DLT point of the region centres, where
        the refinement starts) without the refinement: a batch stopped by its limit reports every point at once."""
        try:
            norm = self.normalization()
            if self.deadline.expired:
                return norm.world_point(np.zeros(3))
            est = local_estimate(norm.cameras(self.C), norm.regions(self.regions))
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            return None
        return None if est is None else norm.world_point(est[1])

    def offer_new(self) -> None:
        est = self.bounds.take_estimates()
        if est:
            self.offer_screened(np.array([X for _, X in est]))

    def offer_screened(self, Xs: np.ndarray) -> None:
        """Offer the :data:`LO_STARTS` best of the candidates ``Xs`` (M, 3) by :meth:`screen`."""
        if not len(Xs):
            return
        f = self.screen(Xs)
        for k in np.argsort(f)[:LO_STARTS]:
            if f[k] < self.best_f * (1 + 1e-9):        # the screen is only a ranking: exact costs decide
                self.offer(Xs[k])

    def inlier_set(self, X) -> frozenset:
        d = self.residuals(X)
        return frozenset(int(i) for i in np.nonzero(d < self.c)[0])

    # ------------------------------------------------------------------ candidates
    def need(self, subsets):
        """Generator: hand the subsets whose bounds are not cached yet to the driver (:func:`drive`), which fills
        the cache -- batched with the requests of other problems -- and resumes."""
        todo = [S for S in subsets if not self.bounds.known(S)]
        if todo and self.deadline.expired:   # past the deadline (its own or the whole call's): the valid bound 0,
            for S in todo:                   # no solve; the search then stops with its time limit (finding F4)
                self.bounds._store(S, 0.0, None)
            return
        if todo:
            # a bound >= UB + max c^2 saturates every use (node_bound: lb_I > s_hi, a_u >= s_hi + c_u^2)
            self.bounds.enough = self.best_f + self.c2_max
            if self.bounds.hint is not None:
                self.bounds.hint = self.best_S
            yield todo

    def verify_first(self, *subsets):
        """Generator: the bounds of the subsets by verification only (left unknown where that does not certify:
        a later :meth:`need`, with a candidate known, may settle them by their pair packing instead of an SDP)."""
        todo = [S for S in subsets if not self.bounds.known(S)]
        if robust_bounds.PACKING:
            self.bounds.defer.update(todo)
        yield from self.need(todo)

    def candidates(self, rng):
        full = frozenset(range(self.N))
        if not robust_suspects.skip_full(self):           # all views verified unless a view is over its threshold
            yield from self.verify_first(full)
        if self.bounds.known(full):
            self.offer(self.bounds.estimate(full))
            if self.best_X is not None and self.meets(self.root_bound()):
                return                          # certified by the L2 certificate of all views: no search needed
            if robust_futile.settle_best_set(self):
                pass                            # L2LB(V) exhausted below UB: the leave-one-out bound (<= it) is moot
            elif self.best_S == full and self.N >= 3 and robust_bounds.PACKING and robust_suspects.ENABLED:
                self.loo_lb = yield from leave_one_out(self, full, 0.0)       # its sub-bounds from halves first
            elif self.best_S == full and self.N >= 3 and robust_bounds.PACKING:
                yield from self.verify_first(*[full - {j} for j in range(self.N)])
                self.offer_new()
                self.loo_lb = self.leave_one_out_bound()
                if self.meets(self.loo_lb):
                    return                      # every view an inlier, and dropping any costs at least as much
        if robust_suspects.ENABLED and robust_bounds.PACKING:           # a few wrong matches: O(N) sub-problems
            self.loo_lb = max(self.loo_lb, (yield from robust_suspects.suspect_bound(self)))
            if self.meets(self.loo_lb):
                return
        if self.deadline.expired:               # past the limit: no pair stage (79,800 pairs at N = 400)
            return
        yield from self.need(sampled_pairs(self.N, rng, MAX_PAIRS))
        est = self.bounds.take_estimates()
        starts = []
        if est:
            Xs = np.array([X for _, X in est])
            f = self.screen(Xs)      # past the deadline one start (each offer: one report, ~1.3 ms at 100 regions)
            starts = [Xs[k] for k in np.argsort(f)[:1 if self.deadline.expired else LO_STARTS]]
            for X in starts:
                self.offer(X)
        yield from self.local_optimisation(starts + ([self.best_X] if self.best_X is not None else []))
        for X in [] if self.deadline.expired else ray_candidates(self):   # |S| = 1: on one view's ray (robust_rays)
            self.offer(X)

    def local_optimisation(self, starts):
        """Local optimisation (inlier set -> L2 estimate of the set -> inlier set, :data:`LO_ROUNDS` rounds) from
        every start in lockstep: the sets of one round of all chains are one request."""
        seen = [set() for _ in starts]
        chains = list(range(len(starts)))
        Xs = list(starts)
        for _ in range(LO_ROUNDS):
            if self.deadline.expired:
                return
            sets = {}
            for k in chains:
                S = self.inlier_set(Xs[k])
                if len(S) >= 2 and S not in seen[k]:
                    seen[k].add(S)
                    sets[k] = S
            if not sets:
                return
            yield from self.need(list(dict.fromkeys(sets.values())))
            chains = []
            for k, S in sets.items():
                Xs[k] = self.bounds.estimate(S)
                self.offer(Xs[k])
                if Xs[k] is not None:
                    chains.append(k)

    # ------------------------------------------------------------------ bounds
    def search(self, order: np.ndarray):
        """Depth-first branch and bound (module docstring): (global lower bound, why it stopped early or None)."""
        # a node: (I, O, c^2(O), next view in the order, parent's bound, lower bound of L2*(I), of L2*(I + {u}))
        stack = [(frozenset(), frozenset(), 0.0, 0, 0.0, 0.0, np.zeros(self.N))]
        floor = math.inf                            # min bound of nodes pruned below UB / leaves left open
        stopped = None
        while stack:
            if self.nodes >= self.bounds.node_budget(self.max_nodes):  # smaller with coplanar centres
                stopped = self.bounds.node_budget_name
                break
            if self.deadline.expired:
                stopped = "time limit"
                break
            I, O, c2_out, k, _, lb_I, a = stack.pop()
            self.nodes += 1
            U = [int(u) for u in order[k:]]
            if not U and len(I) >= 2:
                yield from self.need([I])
                self.offer_new()                    # the leaf's own L2 estimate may be the TLS optimum
                lb_I = max(lb_I, self.bounds.bound(I))
            # a node holding the best candidate cannot be pruned before its leaf: no sub-problems for it
            on_path = I <= self.best_S and not (O & self.best_S)
            lb, lb_I, a = yield from self.node_bound(I, c2_out, U, lb_I, a, refine=not on_path or not U)
            if self.meets(lb):
                if lb < self.best_f:
                    floor = min(floor, lb)
                continue
            if not U:                                # a leaf whose L2 bound does not meet UB
                if self.bounds.reopen(I):            # its packing bound only: verification / SDP now
                    yield from self.need([I])        # lb_I already holds the packing bound
                    self.offer_new()
                    lb = min(self.best_f, c2_out + max(lb_I, self.bounds.bound(I)))
                    if self.meets(lb):
                        if lb < self.best_f:
                            floor = min(floor, lb)
                        continue
                if self.bounds.strengthen(I, (self.best_f - c2_out) / ROUND_DOWN):
                    lb = min(self.best_f, c2_out + self.bounds.bound(I))
                    self.offer_new()
                if not self.meets(lb) or lb < self.best_f:
                    floor = min(floor, lb)
                if robust_futile.leaf_futile(self, I, lb):
                    stopped = robust_futile.FUTILE
                    break
                continue
            u = U[0]
            stack.append((I, O | {u}, c2_out + self.c2[u], k + 1, lb, lb_I, a))
            stack.append((I | {u}, O, c2_out, k + 1, lb, *self.child_bounds(u, lb_I, a)))
        open_lb = min((node[4] for node in stack), default=math.inf)
        return min(self.best_f, floor, open_lb), stopped

    # ------------------------------------------------------------------ the run
    def run(self):
        """Generator (:func:`drive`): yields subset requests, returns the :class:`TriangulationResult`."""
        rng = np.random.default_rng(0)
        t = time.perf_counter()
        if not self.points:          # its normalisation now, not past a deadline that cut the candidates short
            _ = self.scale
            self.offer_screened(centre_pair_candidates(self))     # an anytime candidate with an inlier set
        yield from self.candidates(rng)
        t_cand = time.perf_counter() - t
        if self.best_X is None:                 # candidates cut short (deadline): the sub-problems' estimates so far
            self.offer_new()
        if self.best_X is None:                 # none, or none finite: a local estimate
            self.offer(self.fallback_estimate())
        if self.best_X is None:
            return TriangulationResult("tls", Status.NUMERICAL_FAILURE, message="no finite candidate estimate found",
                                       timings={"total": time.perf_counter() - self.t0})
        # with the hint set, a whole problem holding a likely outlier gets its pair packing bound, no SDP: the root
        # bound uses it only up to min c^2, and the search reopens it if its leaf is not pruned by it
        self.bounds.hint = self.best_S
        if not self.meets(self.loo_lb):                 # certified by the candidate stage: no root bound needed
            yield from self.need([frozenset(range(self.N))])
            self.offer_new()
        if not self.meets(self.loo_lb) and robust_suspects.ENABLED and robust_bounds.PACKING:
            self.loo_lb = max(self.loo_lb, (yield from robust_suspects.cover_bound(self)))   # many wrong matches
        full = frozenset(range(self.N))                 # (review 31a F4: a stop by the rule reported lb = 0)
        lb, stopped = max(self.root_bound() if self.bounds.known(full) else 0.0, self.loo_lb), None
        cells = None if self.meets(lb) else robust_cells.search_bound(self)    # point regions (robust_cells)
        # the cells' bound comes from compensated frames (robust_cells.frame): a certificate resting on it is not
        # judged by the search's own plain-arithmetic value (robust_report.search_drift)
        self.cells_decided = cells is not None and cells.lb > lb and self.meets(cells.lb)
        lb = lb if cells is None else max(lb, cells.lb)
        robust_cells.set_node_budget(self, cells, MAX_NODES)     # short where the cells could not close
        if not self.meets(lb) and robust_futile.blocks(self):     # lb stays valid; the rule may have raised L2LB(V)
            stopped, lb = robust_futile.FUTILE, max(lb, self.root_bound() if self.bounds.known(full) else 0.0)
        elif not self.meets(lb):
            order = branching_order(self.residuals(self.best_X) / self.c)
            yield from self.anchor_bounds(order)
            lb_bb, stopped = yield from self.search(order)
            lb = max(lb, lb_bb)
        if not self.meets(lb):      # the estimate reported uncertified: the L2 optimum of its own set (review 36a F3)
            yield from self.local_optimisation([self.best_X])
        timings = {"candidates": t_cand, "total": time.perf_counter() - self.t0}
        return self.result(lb, stopped, timings, split=robust_suspects.cover_split(self))

    def result(self, lb: float, stopped, timings, note: str = "", split: tuple | None = None) -> TriangulationResult:
        """The result at the search's lower bound ``lb`` (pixels^2): the decision by the one rule on this search's
        scale, the reported numbers and their checks (:func:`~.robust_report.tls_reported`, with an enumeration's
        ``split`` of its bound; a stack of point searches: :func:`~.robust_report.tls_reported_stack`, then
        :meth:`finish`), the message (``note``: what decided)."""
        X = self.user_estimate()
        rep = self.report(X)
        if robust_front.front_tie(self, lb, rep.depths):     # on a line of minimisers: in front (review 36a F2)
            X = self.user_estimate()
            rep = self.report(X)
        told = tls_reported(self.C_user, self.x if self.points else np.array([r.center for r in self.regions]),
                            None if self.points else rep.residuals, X, self.c, lb, self.tol,
                            self.tol.certified_one(lb, self.best_f, self.scale),    # lb valid also when stopped
                            None if self.cells_decided else self.best_f,
                            None if self.points else self.regions, None if self.frame.moved else self.enum_terms,
                            split)
        return self.finish(X, rep, told, lb, stopped, timings, note)

    def user_estimate(self):
        """The best estimate in the caller's frame (None: no candidate)."""
        return self.frame.user_point(self.best_X) if self.frame.moved else self.best_X

    def finish(self, X, rep: PointReport, told, lb: float, stopped, timings, note: str = "") -> TriangulationResult:
        """:meth:`result` from the reported numbers ``told`` of X (:mod:`tritools.solve.robust_report`) and its
        :meth:`report` ``rep``: status, certificate, message."""
        ub = self.best_f
        certified = self.tol.certified_one(lb, ub, self.scale)
        inliers = told.inliers
        if not certified and stopped is None:   # the deadline cut a step short, or a sub-problem hit the memory budget
            # (or its share of the time: more time could certify, so the time limit's status, review 38b M1)
            stopped = "time limit" if self.deadline.expired or self.bounds.deadline.expired or \
                self.bounds.timed_out else "memory budget" if self.bounds.budget_exceeded else None
        # also against the compensated value: best_f's plain arithmetic can fall below a rigorous lb (review 12 F3)
        f_told = 2.0 * self.N * told.gamma_ub ** 2 if math.isfinite(told.gamma_ub) else math.inf
        contradicts = self.tol.contradicts_one(lb, max(ub, f_told), self.scale)
        status = Status.NUMERICAL_FAILURE if contradicts else Status.OPTIMAL if certified else \
            {"time limit": Status.TIME_LIMIT, "memory budget": Status.BUDGET_EXCEEDED}.get(stopped,Status.NOT_CERTIFIED)
        certified = certified and not contradicts
        if certified and not told.holds:                # the reported numbers' checks (robust_report)
            status, certified = Status.NOT_CERTIFIED, False
        gamma_ub, gamma_lb = told.gamma_ub, told.gamma_lb
        status, in_front = cheirality(status, rep.depths[inliers], self.opts.require_in_front)
        msg = f"TLS: {int(inliers.sum())}/{self.N} inliers, {self.nodes} nodes, {self.bounds.n_solved} L2 " \
              f"sub-problems"
        if stopped == robust_futile.FUTILE:
            msg += f"; {robust_futile.futile_message(self)}"
        elif stopped:
            msg += f"; stopped by the {stopped}"
        if told.reason and not certified:
            msg += f"; {told.reason}"
        elif certified and not in_front:               # as the L2 message says it (review 33a L9)
            msg += f"; {behind_message(np.where(inliers, rep.depths, 1.0), 'TLS')}"
        attempt = Attempt("tls", None, status.value, gamma_lb, gamma_ub, "branch-and-bound", None, (),
                          timings["total"])
        return TriangulationResult("tls", status, X=X, gamma_ub=gamma_ub, gamma_lb=gamma_lb, optimal=certified,
                                   image_points=told.image_points, message=msg + note,
                                   certified_by="branch-and-bound" if certified else None,
                                   timings=timings, attempts=(attempt,), in_front=in_front,
                                   depths=rep.depths, residuals=told.residuals, inliers=inliers)


def triangulate_robust(cams: np.ndarray, regions, c: np.ndarray, opts, t0: float | None = None) -> TriangulationResult:
    """Certified TLS triangulation of one point (module docstring) for validated cameras and regions and the
    thresholds of :func:`robust_thresholds`.  With every threshold infinite it is the L2 path (its result,
    every view an inlier)."""
    import dataclasses
    from .robust_enum_run import enumerate_one
    from .robust_settle import settle_by_l2
    from .robust_subsolve import subsolve_of
    from .triangulate import triangulate
    t0 = time.perf_counter() if t0 is None else t0
    if not np.any(np.isfinite(c)):
        res = triangulate(cams, regions, options=opts)
        return dataclasses.replace(res, inliers=None if res.residuals is None else np.ones(len(regions), bool))
    root = None
    if not all(r.is_point for r in regions):            # settled by its L2 certificate, as in a batch
        settled, root = settle_by_l2(cams, regions, c, opts)
        if settled is not None:
            return settled
    with np.errstate(all="ignore"):     # as in robust_batch.robust_many: finiteness is checked, warnings are noise
        search = TlsSearch(cams, regions, c, opts, t0)      # a few views: every inlier set enumerated (robust_enum_run)
        search.set_deadline(call_deadline(opts, t0, regions))   # the time limit counts from the call's entry
        if root is not None:                            # that L2 solve is the search's root: not solved twice
            search.bounds.seed(frozenset(range(len(regions))), subsolve_of(root, len(regions), light=True))
        from . import robust_batch
        res = enumerate_one(search)
        res = drive([search])[0] if res is None else robust_batch.searched_again_one(search, res)
        return res if res.optimal else robust_batch.enumerated_again(search, res)


