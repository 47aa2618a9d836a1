"""The enumeration of every inlier set (:mod:`tritools.solve.robust_enum`) run over many TLS searches at once.

:func:`enumerate_many` takes :class:`tritools.solve.robust.TlsSearch` objects of point problems with 2 to
:data:`~tritools.solve.robust_enum.ENUM_MAX_VIEWS` views (a batch: up to ``max_views``,
:data:`tritools.solve.robust_batch.BATCH_ENUM_MAX_VIEWS`) and, per view count N, stacks the rows of every problem
(each row a masked N-view problem in its own problem's normalised frame) into one call per step; a single call
(:func:`enumerate_tls`) is the batch of one.  Per problem the maths is exactly that of the module docstring of
:mod:`tritools.solve.robust_enum` -- only the stacking is shared:

1. the frames of all problems (:func:`~tritools.solve.robust_enum.enum_frames`), then the candidates (masked
   stacks over every problem), each stack's best refined on its inlier set by local optimisation (inlier set ->
   its L2 optimum -> inlier set) and offered (UB).  One problem: the pairs and all views in one stack, then the
   sets whose c^2(V - S) alone does not meet UB where the best set leaves out :data:`LATER_FROM` views or more.
   Several problems (the staged order, fewer rows): all views first -- a clean track with UB <= min c^2 is decided
   by that one row's bound --, then all views but one, then the pairs (only those holding the view outside the
   inlier set when there is exactly one);
2. the Lagrangian bounds where they matter (one stacked verification over every problem, the fundamental
   matrices of each problem computed once; a row's candidate computed first where missing): the pairs holding a
   view outside the best inlier set and the sets inside it, then the other sets whose c^2(V - S) does not meet UB
   only where the closure of those does not meet it; closed under superadditivity, LB against UB at the floor of
   the decision scale (:meth:`_Group._decide`);
3. for the problems still open: the bounded rows whose term does not meet UB refined to convergence on their own
   sets, offered and bounded again (:meth:`_Group._second_chance`: a row's polish may stop short of its set's
   optimum), the bounds of the sets inside a set whose term does not meet UB (only they feed its closure), the
   closure again, the decision at the floor scale and else at the documented
   ``decision_scale`` (a batch gives it for all of them in one call: ``scales``).

A problem not decided (or whose deadline passed between the stacks) gets None: the caller runs its branch and
bound, which starts from the candidates offered here.  The lower bound is rounded down at every sum, the
decision is the one rule of :meth:`tritools.solve.robust.TlsSearch.result`: the rigour of one problem does not
depend on the others of its stack (each row's numbers are its own problem's).
"""
from __future__ import annotations

import logging
import time

import numpy as np

from ..model.normalize import SCALE_BOUNDS
from . import robust_enum as enum
from .robust_bounds import ROUND_DOWN
from .robust_costs import point_distances2_rows, point_distances2_stack
from .robust_drive import credit     # (the drive's rule: per-problem time limits)
from .robust_report import enumerated_result, enumerated_results, exact_sets_bound, outside_split
from .robust_two import two_view_rays

__all__ = ["enumerate_tls", "enumerate_one", "enumerate_many", "eligible", "closed_terms", "lower_bounds",
           "enumerated_result", "enumerated_results", "ENUM_CHUNK", "ENUM_ROWS", "SINGLE_POLISH_STEPS",
           "THREE_VIEW_PATH", "ASCENT_ROWS"]

log = logging.getLogger(__name__)

#: at most this many problems share one stack; each stacked candidate, verification or refinement call takes at most
#: ENUM_ROWS of its rows (a stacked verification of R rows of N views holds ~R N^3 floats: 8192 rows at N = 10,
#: ~60 MB), the rows of a stack in turn (:func:`_by_rows`).  A stack of many problems bounds few of its 2^N - N - 1
#: rows per problem (the staged order), so the stack's size is not tied to the number of subsets: small stacks at
#: 9-10 views (8 problems of 1013 rows) spent more on each stack's fixed steps than on the rows (wave 9).
ENUM_CHUNK = 256
ENUM_ROWS = 8192
#: stacks of at least this many problems take the staged order (all views first, then all views but one, the pairs
#: only where they matter: fewer rows); a single problem takes one stack of the pairs and all views (fewer calls).
#: Measured on single calls, the two orders interleaved (median CPU ms, 30 tracks per cell, loaded machine): one
#: stack 2.2 / 3.3 / 4.8 against staged 2.7 / 4.3 / 5.4 on protocol tracks with outliers at N = 3 / 5 / 7, equal on
#: clean tracks; in batches the staged order is the cheaper one (benchmarks/RESULTS.md, wave 7).
STAGED_FROM = 2
#: a single call computes the candidates of the sets whose c^2(V - S) does not meet UB (they may lower it) only when
#: its best inlier set leaves out at least this many views (measured, 0 against 3: N = 5-8 1.9-2.7 ms against
#: 2.3-3.4, the same answers; without them, N = 7 with three wrong matches left 3 of 40 scenes to the search).
LATER_FROM = 3
#: Levenberg-Marquardt steps polishing the rows of a single problem (a stack of many: enum.POLISH_STEPS, 5): its best
#: candidate is refined to convergence on its inlier set, and the rows whose bound then fails on their own sets
#: (:meth:`_Group._second_chance`), so the other rows' polish only ranks them and seeds their bounds.  Measured
#: (protocol scenes, one or two wrong matches, 1 and 5 px, 160 single calls per setting, median CPU, interleaved):
#: N = 5: 5 steps 3.00-3.07 ms, 2 steps 2.78-2.89, 1 step 2.73; N = 7: 3.36-3.47, 3.11-3.14, 3.03.
SINGLE_POLISH_STEPS = 1
#: single calls of two and three views take :mod:`tritools.solve.robust_three` (False: the stack of one; the tests
#: compare).
THREE_VIEW_PATH = True
#: rounds of local optimisation of the best candidate of a stack (inlier set -> its L2 optimum -> inlier set).
LO_ROUNDS = 3
#: :meth:`_Group._solve_all` from three views on (False: three views' set of all views only; the tests compare).
SOLVE_LAST_SET = True


def eligible(search, max_views: int | None = None) -> bool:
    """Does the enumeration run for this search (point regions, 2 to ``max_views`` views -- None: ENUM_MAX_VIEWS --,
    time left)?"""
    top = enum.ENUM_MAX_VIEWS if max_views is None else max_views
    return bool(search.points and 2 <= search.N <= top and not search.deadline.expired)


def enumerate_tls(search):
    """The TLS result of one :class:`tritools.solve.robust.TlsSearch` by enumeration, or None (the caller runs the
    search, which has been offered the best candidates found here): :func:`enumerate_many` of one, or for three views
    :func:`tritools.solve.robust_three.three_view_tls` (the same steps without a stack's bookkeeping) where
    :data:`THREE_VIEW_PATH`."""
    if THREE_VIEW_PATH and search.N in (2, 3):
        from .robust_three import three_view_tls, two_view_tls

        return (two_view_tls if search.N == 2 else three_view_tls)(search)
    return enumerate_many([search])[0]


def enumerate_one(search):
    """A single call's enumeration: :func:`enumerate_tls`, then, where that leaves the problem open, the staged order
    of a batch (:func:`enumerate_many` with ``staged=True``) -- each order decides problems the other leaves to the
    search with a worse estimate (review 25a F3: duplicated and negated views with per-view thresholds, where the
    batch certified an estimate 5.9x better in f_TLS than the single call's uncertified one; review 22a F1 the other
    way round), and a batch runs them in the other order (:mod:`tritools.solve.robust_batch`).  The second costs
    only the problems the first leaves open; None when both do (the caller runs the search)."""
    res = enumerate_tls(search)
    if res is None and eligible(search):
        res = enumerate_many([search], staged=True)[0]
    return res


def enumerate_many(searches: list, scales=None, max_views: int | None = None, staged: bool | None = None) -> list:
    """A result or None per search (module docstring), in input order; searches that are not :func:`eligible` (up
    to ``max_views`` views; None: ENUM_MAX_VIEWS) get None.  ``scales(list of searches)``: sets the documented
    decision scale of the searches that need it (a batch: one normalisation stack); None: each search computes its
    own when asked.  ``staged``: True (a batch): every stack in the staged order, so a problem gets the same numbers
    however many problems of its view count its batch holds (review 20 F1); None: from STAGED_FROM problems."""
    out: list = [None] * len(searches)
    groups: dict = {}
    for k, s in enumerate(searches):
        if eligible(s, max_views):
            groups.setdefault((s.N, id(s.tol)), []).append(k)
    for _key, idx in groups.items():
        for a in range(0, len(idx), ENUM_CHUNK):
            part = idx[a:a + ENUM_CHUNK]
            t = time.monotonic()
            for k, r in zip(part, _run([searches[k] for k in part], scales, staged)):
                out[k] = r
            _credit_others(searches, set(part), time.monotonic() - t)
    return out


def _credit_others(searches: list, ran: set, seconds: float) -> None:
    """Time limits stay per problem (as in :func:`tritools.solve.robust_drive.drive`): the searches outside the
    stack that just ran waited for it, and their deadlines move on by its time (within the whole call's end)."""
    for k, s in enumerate(searches):
        if k not in ran:
            credit(s, seconds)


#: rows per problem bounded by the dual ascent in the second round at most (:meth:`_Group._ascend`; each ~0.5-3 ms)
ASCENT_ROWS = 3


def _run(group: list, scales, staged: bool | None = None) -> list:
    """:meth:`_Group.run`; where a stack fails on degenerate data, each problem alone (so that one problem never
    decides another's path); None for a problem that fails alone (its search runs)."""
    try:
        return _Group(group, scales, staged).run()
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        log.debug("enumeration of %d problems failed", len(group), exc_info=True)
        if len(group) == 1:
            return [None]
    return [_run([s], scales, staged)[0] for s in group]


def _by_rows(fn, n: int, *arrays) -> tuple:
    """``fn(*(a[chunk] for a in arrays))`` over chunks of at most :data:`ENUM_ROWS` of the ``n`` rows, each output
    (a tuple of arrays, or one array) concatenated along the rows: one call where n <= ENUM_ROWS."""
    if n <= ENUM_ROWS:
        return fn(*arrays)
    parts = [fn(*(a[k:k + ENUM_ROWS] for a in arrays)) for k in range(0, n, ENUM_ROWS)]
    if isinstance(parts[0], tuple):
        return tuple(np.concatenate(col) for col in zip(*parts))
    return np.concatenate(parts)


def closed_terms(N: int, W: np.ndarray, lb: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """The terms L2LB(S) + c^2(V - S) (P, M) of the sets ``W`` (M, N) of P problems, each bound ``lb`` (P, M) closed
    under superadditivity (:func:`~tritools.solve.robust_enum.closure`), ``rest`` = c^2(V - S) (P, M), rounded
    down (module docstring of :mod:`tritools.solve.robust_enum`)."""
    bits = W.astype(np.int64) @ (1 << np.arange(N))
    table = np.zeros((len(lb), 1 << N))
    table[:, bits] = lb
    # a problem whose bounds are 0 but for all views' (a clean track's first row) is closed already: no split of a
    # set sums two non-zero parts, and no set holds all views but the set of all views
    split = np.any(table[:, :-1] != 0, axis=1)
    if split.any():
        table[split] = enum.closure(N, table[split])
    with np.errstate(over="ignore", invalid="ignore"):
        return (table[:, bits] + rest) * ROUND_DOWN


def lower_bounds(ub: np.ndarray, terms: np.ndarray, c2: np.ndarray) -> np.ndarray:
    """LB (P,): the least of UB (P,), the closed terms (P, M) (:func:`closed_terms`), the exact terms of the sets of
    one view (c^2 of the others) and of the empty set (c^2(V)), c2 (P, N) the squared thresholds (module docstring of
    :mod:`tritools.solve.robust_enum`)."""
    return np.minimum.reduce([ub, np.min(terms, axis=1), exact_sets_bound(c2)])


def _outside_sums(c2: np.ndarray, W: np.ndarray) -> np.ndarray:
    """c^2(V - S) (P, M) of the sets ``W`` (M, N), c2 (P, N), rounded down (inf where a view outside S has c_i =
    inf): one matrix product where every c_i is finite (0 * inf would be NaN there)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(c2).all():
            return (c2 @ (~W).T.astype(float)) * ROUND_DOWN
        return np.sum(np.where(W[None], 0.0, c2[:, None, :]), axis=2) * ROUND_DOWN


class _Group:
    """P searches of one view count N enumerated together: row (p, m) is subset m of problem p."""

    def __init__(self, group: list, scales, staged: bool | None = None):
        self.group, self.scales = group, scales
        self.N = N = group[0].N
        self.tol = group[0].tol
        self.C = np.stack([s.C for s in group])
        self.x = np.stack([s.x for s in group])
        self.c2 = np.stack([s.c2 for s in group])
        self.W = enum.subset_masks(N)
        self.size = self.W.sum(axis=1)
        self.Xn = np.full((len(group), len(self.W), 3), np.nan)
        self.has = np.zeros(self.Xn.shape[:2], bool)     # np.isfinite(Xn).all(axis=2), kept with Xn (:meth:`_put`)
        self.results: list = [None] * len(group)
        self._fundamentals = self._floor = self._terms_cache = None
        self.staged = len(group) >= STAGED_FROM if staged is None else staged
        self.refined: list = [set() for _ in group]     # the inlier sets refined to convergence, per problem
        self._clock = time.monotonic()                   # the stack's time is shared (:meth:`_expired`)

    def run(self) -> list:
        """The results (module docstring, steps 1-3); None where not decided."""
        self.frames, self.Cn = enum.enum_frames(self.C, self.x, self.c2)
        live = np.array([f is not None for f in self.frames])
        self.origin = np.array([f.origin if f is not None else np.zeros(3) for f in self.frames])
        self.depth = np.array([f.depth if f is not None else 1.0 for f in self.frames])
        self.rest = _outside_sums(self.c2, self.W)
        self.lb = np.zeros(self.rest.shape)
        self.bounded = np.zeros(self.rest.shape, bool)
        if self.staged:
            live = self._all_views_first(live)
            if not live.any():              # every clean track decided (the rest have no frame: their search runs)
                return self.results
        live = self._upper_bounds(live)
        if self.N == 2:
            live = two_view_rays(self, live)
        self._second_round(self._first_round(live), live)
        return self.results

    def _all_views_first(self, live: np.ndarray) -> np.ndarray:
        """A stack of several problems: the candidate and the bound of all views first.  A track whose best inlier
        set is all views with UB <= min c^2 is then decided where L2LB(V) meets UB (every other term has
        c^2(V - S) >= min c^2 >= UB): one row per clean track instead of the pairs' stack.  The problems left."""
        full = live[:, None] & (self.size == self.N)[None]
        self._candidates(full)
        self._offer(full)                   # (a problem without a finite candidate here goes on to the pairs)
        live = live & ~self._expired()
        clean = np.array([len(s.best_S) == self.N for s in self.group]) & (self._ub() <= np.min(self.c2, axis=1))
        quick = live & clean
        self._bound(quick[:, None] & full)
        self._decide(np.nonzero(quick)[0], final=False)
        return live & np.array([r is None for r in self.results])

    def _upper_bounds(self, live: np.ndarray) -> np.ndarray:
        """Step 1 (after :meth:`_all_views_first` in a batch): the candidates of the pairs and of all views, then of
        the open sets where the best inlier set leaves out LATER_FROM views or more (one problem), each stack's best
        offered; the problems with a candidate and time left."""
        todo = lambda rows: rows & live[:, None] & ~self.has     # noqa: E731
        pairs = np.broadcast_to((self.size == 2)[None], self.Xn.shape[:2])
        if self.staged:               # a batch: the sets of all views but one next; where the best then has one view
            loo = todo((self.size == self.N - 1)[None])        # outside its inlier set, only the pairs holding it
            self._candidates(loo)
            live = live & (self._offer(loo) | ~loo.any(axis=1))
            out = np.array([[i not in s.best_S for i in range(self.N)] for s in self.group])
            one = (out.sum(axis=1) == 1)[:, None]
            pairs = pairs & (~one | (self.W[None] & out[:, None, :]).any(axis=2))
        first = todo(pairs | (self.size == self.N)[None])
        self._candidates(first)
        live = live & (self._offer(first) | ~first.any(axis=1))
        # the open sets' candidates (they may lower UB) where local optimisation from the pairs is least reliable:
        # a best inlier set that leaves out LATER_FROM views or more (one problem; a batch relies on its LO rounds)
        few = np.array([self.N - len(s.best_S) < LATER_FROM for s in self.group])
        later = todo(self._open()) & ~few[:, None]
        if later.any() and not self.staged:
            self._candidates(later)
            live = live & (self._offer(later) | ~later.any(axis=1))
        return live

    def _first_round(self, live: np.ndarray) -> list:
        """Step 2: the bounds of the sets in need -- the pairs holding a view outside the best inlier set (they feed
        the closure of the sets holding it) and the sets inside it first (their own bounds are the tight ones), then
        the other sets whose c^2(V - S) does not meet UB only where the closure of those does not meet it (a set
        holding a wrong match usually inherits enough from its pairs: its own Lagrangian bound is weak) -- and
        the decision at the floor scale; the problems left open."""
        W, size = self.W, self.size
        best = np.array([[i in s.best_S for i in range(self.N)] for s in self.group])
        inside = ~(W[None] & ~best[:, None, :]).any(axis=2)
        pairs = (size == 2)[None] & ~inside & (self._ub() > np.min(self.c2, axis=1))[:, None]
        need = (self._open() | pairs) & live[:, None]
        self._bound(need & (inside | pairs))
        rest = need & ~self.bounded
        if rest.any():
            self._bound(rest & self._failing())
        return self._decide(np.nonzero(live)[0], final=False)

    def _second_round(self, open_: list, live: np.ndarray) -> None:
        """Step 3: for the problems left open with time left, the candidates and bounds of the sets inside a set
        whose term does not meet UB (:meth:`_feeding`), the closure again; the final decision."""
        keep = np.zeros(len(self.group), bool)
        expired = self._expired()
        keep[[p for p in open_ if not expired[p]]] = True
        if not keep.any():
            return
        self._second_chance(live & keep)
        more = ~self.bounded & (live & keep)[:, None] & self._feeding()
        if more.any():
            self._bound(more)
        self._ascend(live & keep & ~self._expired())
        self._solve_all(live & keep & ~self._expired())
        self._decide(np.nonzero(keep)[0], final=True)

    def _solve_all(self, probs: np.ndarray) -> None:
        """The problems ``probs`` (P,) kept open by one set alone after the ascent (three views, or a wrong match left
        in a larger set): that set's L2 sub-problem solved here (:meth:`~tritools.solve.robust_bounds.SubsetBounds.
        solve_full`, stopping at UB - c^2(V - S)), its estimate offered; two views: the rays and the search."""
        if self.N < 3:
            return
        failing, ub = self._failing(), self._ub()
        one = failing.sum(axis=1) == 1
        if not SOLVE_LAST_SET:
            one &= (self.N == 3) & failing[:, -1]          # (the set of all views, the last row)
        for p in np.nonzero(probs & one)[0]:
            if self._expired()[p]:                      # (the others' solves credited to every deadline)
                continue
            m = int(np.argmax(failing[p]))
            S = frozenset(np.nonzero(self.W[m])[0].tolist())
            X = self.frames[p].world_point(self.Xn[p, m]) if self.has[p, m] else None
            b, Xs = self.group[p].bounds.solve_full(S, float(ub[p] - self.rest[p, m]), X)
            if b > self.lb[p, m]:
                self.lb[p, m] = b
                self._terms_cache = None
            if Xs is not None:
                self._offer_each([(p, Xs)])

    def _ascend(self, probs: np.ndarray) -> None:
        """The bounded rows of the problems ``probs`` (P,) whose term still does not meet UB: their bound by the best
        degree-2 certificate (:func:`~tritools.solve.robust_enum.ascended_bound`, climbing to what the term needs,
        UB - c^2(V - S)) instead of the one at their candidate (a set holding a wrong match: the KKT multipliers
        give no bound, the dual's maximum often passes the need), the larger kept; at most :data:`ASCENT_ROWS`
        rows per problem, the largest sets first (the set of all views is the one a wrong match leaves open)."""
        rows = self._failing() & self.bounded & probs[:, None] & self.has
        if not rows.any():
            return
        F, defined, E = self._fundamentals
        ub = self._ub()
        order = np.argsort(-self.size, kind="stable")
        for p in np.nonzero(rows.any(axis=1))[0]:
            for m in [m for m in order if rows[p, m]][:ASCENT_ROWS]:
                if self.group[p].deadline.expired:
                    break
                b = enum.ascended_bound(self.Cn[p], F[p], defined[p], self.W[m], self.Xn[p, m],
                                        self.frames[p].scale, self.tol, float(ub[p] - self.rest[p, m]), E[p])
                if b > self.lb[p, m]:
                    self.lb[p, m] = b
                    self._terms_cache = None

    def _second_chance(self, probs: np.ndarray) -> None:
        """The bounded rows of the problems ``probs`` (P,) whose term does not meet UB, refined to convergence on their
        own sets (:func:`~.robust_enum.refine_rows`: a row's few polish steps may leave it short of the set's L2
        optimum, and a Lagrangian bound taken there fails or falls short), offered (UB may fall: a set's optimum the
        polish did not reach) and bounded again, the larger of the two bounds kept (both are valid)."""
        rows = self._failing() & self.bounded & probs[:, None] & self.has
        pp, mm = np.nonzero(rows)
        if not pp.size:
            return
        Xr, ok = _by_rows(self._refine_rows, len(pp), self.Cn[pp], self.Xn[pp, mm], self.W[mm])
        pp, mm, Xr = pp[ok], mm[ok], Xr[ok]
        if not pp.size:
            return
        self._put(pp, mm, Xr)
        self._offer_each([(p, self.frames[p].world_point(X)) for p, X in zip(pp, Xr)])
        old = self.lb.copy()
        self.bounded[pp, mm] = False
        again = np.zeros_like(self.bounded)
        again[pp, mm] = True
        self._bound(again)
        self.lb = np.maximum(self.lb, old)
        self._terms_cache = None

    # ------------------------------------------------------------------ steps
    def _expired(self) -> np.ndarray:
        """(P,) each search's deadline passed, each charged its even share of the stack's time since the last
        check: the rest moves its deadline on (as :func:`tritools.solve.robust_drive.drive` does; one problem:
        nothing moves)."""
        now = time.monotonic()
        waited = (now - self._clock) * (1.0 - 1.0 / len(self.group))
        self._clock = now
        if waited > 0:
            for s in self.group:
                credit(s, waited)
        return np.array([s.deadline.expired for s in self.group])

    def _ub(self) -> np.ndarray:
        return np.array([s.best_f for s in self.group])

    def _candidates(self, rows: np.ndarray) -> None:
        """The candidates of the rows (P, M) (:func:`~tritools.solve.robust_enum.enum_candidates`, one stack; a single
        problem's rows polished by :data:`SINGLE_POLISH_STEPS` in one masked stack, a batch's per subset size)."""
        pp, mm = np.nonzero(rows)
        if pp.size:
            if self.staged:
                fn = lambda C, W: enum.enum_candidates(C, W, None, by_size=True)        # noqa: E731
            else:
                fn = lambda C, W: enum.enum_candidates(C, W, SINGLE_POLISH_STEPS)       # noqa: E731
            self._put(pp, mm, _by_rows(fn, pp.size, self.Cn[pp], self.W[mm]))

    def _put(self, pp, mm, X: np.ndarray) -> None:
        """Xn[pp, mm] = X, and its finiteness in ``has`` (a (P, M, 3) finiteness test per step cost ~4 ms at 200
        problems of 10 views)."""
        self.Xn[pp, mm] = X
        self.has[pp, mm] = np.isfinite(X).all(axis=-1)

    def _offer(self, rows: np.ndarray) -> np.ndarray:
        """Offer each problem the best of its candidates in ``rows`` (P, M) (world frame, ranked by f_TLS in one
        stacked evaluation), refined to convergence on its inlier set S (:func:`_refine`: its f_TLS is at most the
        candidate's), and put the refined point in the row of S (whose bound is then taken at the L2 optimum); the
        candidate itself where that fails.  The problems that may go on: a candidate and time left."""
        pp, mm = np.nonzero(rows & self.has)
        picks = []
        if pp.size:
            world = self.origin[pp] + self.depth[pp, None] * self.Xn[pp, mm]
            d2 = point_distances2_stack(self.C[pp], self.x[pp], world[:, None])[:, 0]           # (R, N)
            f = np.sum(np.minimum(d2, self.c2[pp]), axis=1)       # (only ranks: offer() computes it exactly)
            order = np.lexsort((f, pp))
            first = enum.first_of_runs(pp[order])
            for r in order[first]:
                picks.append((int(pp[r]), world[r], np.nonzero(d2[r] < self.c2[pp[r]])[0].tolist()))
        self._offer_each([(p, X) for p, X, _ in picks])
        for _ in range(LO_ROUNDS):                      # inlier set -> its L2 optimum -> inlier set
            picks = [(p, X, S) for p, X, S in picks if len(S) >= 2 and frozenset(S) not in self.refined[p]]
            for p, _, S in picks:                       # (a set refined before: its optimum was offered then)
                self.refined[p].add(frozenset(S))
            refined = self._refine(picks)
            picks = [(p, S, refined[p], self.frames[p].world_point(refined[p])) for p, _, S in picks if p in refined]
            self._offer_each([(p, Xw) for p, _, _, Xw in picks])
            again = []
            for p, S, Xr, Xw in picks:
                s = self.group[p]
                self._put(p, enum.row_of(self.N)[sum(1 << i for i in S)], Xr)
                if s.best_S != frozenset(S) and np.array_equal(s.best_X, Xw):
                    again.append((p, s.best_X, sorted(s.best_S)))          # a new best with another inlier set
            picks = again
        return np.array([s.best_X is not None for s in self.group]) & ~self._expired()

    def _offer_each(self, offers: list) -> None:
        """Offer each (problem, world point) in turn (:meth:`TlsSearch.offer`), their squared distances from one
        :func:`~tritools.solve.robust_costs.point_distances2_rows` (the twin of the search's own)."""
        finite = [(p, X) for p, X in offers if np.isfinite(X).all()]
        if not finite:
            return
        P = np.array([p for p, _ in finite])
        d2 = point_distances2_rows(self.C[P], self.x[P], np.array([X for _, X in finite]))
        for (p, X), d in zip(finite, d2):
            self.group[p].offer(X, d)

    def _refine(self, picks: list) -> dict:
        """problem -> the candidate refined on its inlier set S (normalised, :func:`~.robust_enum.refine_rows`); absent
        where it fails."""
        if not picks:
            return {}
        P = np.array([p for p, _, _ in picks])
        inS = np.zeros((len(picks), self.N), bool)
        for r, (_, _, S) in enumerate(picks):
            inS[r, S] = True
        X0 = np.array([self.frames[p].normalized_point(X) for p, X, _ in picks])
        Xn, ok = self._refine_rows(self.Cn[P], X0, inS)
        return {int(p): Xn[r] for r, p in enumerate(P) if ok[r]}

    def _refine_rows(self, Cn: np.ndarray, X0: np.ndarray, inS: np.ndarray) -> tuple:
        """:func:`~.robust_enum.refine_rows`, by its stacked code in a batch however many rows there are (a problem
        then gets the same numbers in any batch), by the scalar twin for a single call's row."""
        return enum.refine_rows(Cn, X0, inS, scalar=False if self.staged else None)

    def _bound(self, rows: np.ndarray) -> None:
        """The Lagrangian bounds of the rows (P, M) not bounded yet (one stacked verification,
        :func:`~tritools.solve.robust_enum.enum_bounds_rows`), their candidates first where missing."""
        rows = rows & ~self.bounded
        self.bounded |= rows
        self._candidates(rows & ~self.has)
        pp, mm = np.nonzero(rows)
        if not pp.size:
            return
        if self._fundamentals is None:                 # once per problem, of the problems with frames
            F = np.zeros(self.Cn.shape[:1] + (len(enum.view_pairs(self.N)[0]), 3, 3))
            defined = np.zeros(F.shape[:2], bool)
            E = np.full(F.shape[:2], np.inf)
            has = np.array([f is not None for f in self.frames])
            F[has], defined[has], E[has] = enum.fundamentals(self.C[has], self.Cn[has])
            self._fundamentals = F, defined, E
        F, defined, E = self._fundamentals
        s = np.array([f.scale if f is not None else 1.0 for f in self.frames])
        self._terms_cache = None
        self.lb[pp, mm] = _by_rows(lambda C, W, X, sc, p: enum.enum_bounds_rows(
            C, F, defined, W, X, sc, self.tol, problem=p, by_size=self.staged, accepted=False, errors=E)[0],
            pp.size, self.Cn[pp], self.W[mm], self.Xn[pp, mm], s[pp], pp)

    def _floors(self) -> np.ndarray:
        """The floor of each problem's decision scale (:mod:`tritools.solve.robust_enum`, "The decision scale")."""
        from .robust import scale_from

        if self._floor is None:
            self._floor = np.array([scale_from(SCALE_BOUNDS[1], s.c2) for s in self.group])
        return self._floor

    def _open(self) -> np.ndarray:
        """The rows (P, M) whose term c^2(V - S) alone does not meet UB under the rule at the floor scale (finite
        only)."""
        ub = self._ub()[:, None]
        met = (self.rest >= ub) | np.asarray(self.tol.certified(self.rest, ub, self._floors()[:, None]), bool)
        return ~met & np.isfinite(self.rest)

    def _terms(self) -> np.ndarray:
        """The terms L2LB(S) + c^2(V - S) (P, M) of every set, its bound closed (module docstring of
        :mod:`tritools.solve.robust_enum`), rounded down; computed again only after new bounds."""
        if self._terms_cache is None:
            self._terms_cache = self._closed_terms()
        return self._terms_cache

    def _closed_terms(self) -> np.ndarray:
        """:func:`closed_terms` of the problems not decided yet; a decided problem's terms (never read again) are
        its bounds unclosed plus c^2(V - S), rounded down (still valid, without the closure's cost)."""
        open_ = np.array([r is None for r in self.results])
        with np.errstate(over="ignore", invalid="ignore"):
            terms = (self.lb + self.rest) * ROUND_DOWN
        if open_.any():
            terms[open_] = closed_terms(self.N, self.W, self.lb[open_], self.rest[open_])
        return terms

    def _lower_bounds(self) -> np.ndarray:
        """LB (P,) (:func:`lower_bounds`)."""
        return lower_bounds(self._ub(), self._terms(), self.c2)

    def _failing(self) -> np.ndarray:
        """The sets (P, M) whose term does not meet UB at the floor scale."""
        terms, ub = self._terms(), self._ub()[:, None]
        return (terms < ub) & ~np.asarray(self.tol.certified(terms, ub, self._floors()[:, None]), bool)

    def _feeding(self) -> np.ndarray:
        """The sets (P, M) inside a set whose term does not meet UB at the floor scale: only their bounds can raise
        a term that matters (the closure of S reads S's subsets only; a term that meets UB already meets it)."""
        # (float32 counts, exact below 2^24: BLAS, where an integer product of a stack of 256 problems at N = 10
        # took ~0.3 s)
        return (self._failing().astype(np.float32) @ enum.subset_of(self.N).T.astype(np.float32)) > 0

    def _decide(self, probs, final: bool) -> list:
        """Decide the problems ``probs`` where LB meets UB (at the floor scale: the documented rule then holds too;
        ``final``: else at the documented scale, ``scales`` asked once for all of them); the problems left open."""
        if not len(probs):
            return []
        lb_all, floors = self._lower_bounds(), self._floors()
        late, met = [], []
        for p in probs:
            s, lb, ub = self.group[p], float(lb_all[p]), self.group[p].best_f
            if s.tol.certified_one(lb, ub, floors[p]) and not s.tol.contradicts_one(lb, ub, floors[p]):
                s.set_normalization_scale(SCALE_BOUNDS[1])       # met at the floor: met at the documented scale
                met.append(p)
            else:
                late.append(p)
        self._results(met, lb_all)
        if not final:
            return late
        if self.scales is not None:
            self.scales([self.group[p] for p in late])
        # the search's rule (TlsSearch.meets): a gap the report's guard would refuse goes on to the branch and bound
        self._results([p for p in late if self.group[p].meets(float(lb_all[p]))], lb_all)
        return [p for p in late if self.results[p] is None]

    def _results(self, probs: list, lb_all: np.ndarray) -> None:
        """The results of the decided problems ``probs`` at their lower bounds (:func:`enumerated_results`), each
        search told the split of its bound by the views outside its best inlier set (:func:`outside_split`)."""
        if probs:
            terms = self._terms()
            splits = [outside_split(self.W, terms[p], [i not in self.group[p].best_S for i in range(self.N)],
                                    self.group[p].c2, self.lb[p]) for p in probs]
            done = enumerated_results([self.group[p] for p in probs], lb_all[probs], self.bounded[probs].sum(axis=1),
                                      len(self.W), splits)
            for p, r in zip(probs, done):
                self.results[p] = r
