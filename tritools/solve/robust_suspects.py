"""The TLS search's suspect-set stage: a track with a few wrong matches certified from O(N) sub-problems.

A track whose L2 estimate of all views V leaves views over their thresholds usually holds one to three wrong
matches, and the full branch and bound of :mod:`tritools.solve.robust` reaches their certificate only after
every view pair (N(N-1)/2 sub-problems), the local optimisation and a few dozen nodes.  This stage tries a
two-node cover of the inlier sets first.

The suspects.  Starting from the best candidate (the L2 estimate of V), O is the set of views it calls
outliers; W = V - O is verified, its estimate offered, and O re-read from the best candidate, for at most
:data:`ROUNDS` rounds (it stops when O is stable).  Only |O| <= :data:`MAX_SUSPECTS` goes on.

The bound.  For *any* set O of views, every X either keeps some j in O an inlier (d_j(X) < c_j) or has every
view of O as an outlier, so

    f_TLS* >= min( min_{j in O} LB(node I = {j}),   c^2(O) + TLS*(W) ),

where LB(node I = {j}) is the module docstring's node bound of :mod:`tritools.solve.robust` with I = {j},
O = {} and U = V - {j} (s = d_j^2 in [0, min(c_j^2, UB)], a_u = L2LB({j, u}): the view pairs holding j only,
at most N - 1 of them, not N(N-1)/2: first the :data:`PAIRS_FIRST` with W's most confident inliers, the rest
only where these do not prune the node; an unknown a_u counts 0), and TLS*(W), the TLS optimum of the views W
alone, is bounded below by the root bound of W, min(L2LB(W), min_{i in W} c_i^2), or, when that is not enough and
L2LB(W) is, by the leave-one-out bound of W (sub-bounds from two halves first, :mod:`tritools.solve.robust_loo`),

    TLS*(W) >= min( L2LB(W), min_{k in W} [ c_k^2 + min(L2LB(W - k), min_{i in W - k} c_i^2) ] ),

the argument of :meth:`tritools.solve.robust.TlsSearch.leave_one_out_bound` on W (an X with an outlier k in W
pays c_k^2 plus the root bound of W - k).  Sub-bounds the verification does not certify count 0 (valid, only
weaker): the stage never solves an SDP; a track it does not certify goes on to the full search, which reuses
every sub-bound cached here.  The result is rounded down (:data:`tritools.solve.robust_bounds.ROUND_DOWN`).
The validity does not depend on how O was chosen: O only decides how tight the bound is.  The two parts are kept
with the bound (:func:`_told`): the report lowers each by the round-off of its own views' coordinates (a wrong match
1e7 px off moves only the pair bounds holding it, which sit far above the thresholds; review 49b M1).
"""
from __future__ import annotations

import math

import numpy as np

from . import robust_bounds
from .robust_bounds import ROUND_DOWN
from .robust_loo import kept_bound, leave_one_out
from .robust_split import Split

__all__ = ["skip_full", "suspect_bound", "cover_bound", "cover", "cover_split", "ENABLED", "MAX_SUSPECTS",
           "PAIRS_FIRST", "ROUNDS", "SMALL_N"]

#: False skips the stage (the tests compare the two).
ENABLED = True
#: the stage runs only for tracks whose best candidate has at most this many outlier views.
MAX_SUSPECTS = 3
#: up to this many views, a track whose rounds found no suspect set tries every leave-one-out fit (with few views
#: the worst view of the L2 fit is often a clean one).
SMALL_N = 4
#: view pairs {j, u} per suspect j requested first (the rest only where these do not bound the node {j}).
PAIRS_FIRST = 3
#: rounds of (verify W = V - O, offer its estimate, re-read O) before the bound.
ROUNDS = 3
#: :func:`cover_bound`: a candidate outlier j with d_j / c_j below this stays with the inliers in a second try
AMBIGUOUS = 2.0


def skip_full(search) -> bool:
    """Is the verification of all views V skipped at the start of the search?  Where the parent's L2 estimate
    X_V (its normalisation's, point regions) has a view over its threshold, the root bound min(L2LB(V),
    min c^2) cannot certify it (a view with d_i(X_V) >= c_i leaves f_TLS(X_V) below L2*(V), and UB <= c^2 would be
    needed), and the verification of a track with a wrong match rarely succeeds: X_V is offered instead and the
    suspect stage starts from it.  L2LB(V) is computed later where the search still needs it."""
    frame = search.bounds.frame() if ENABLED and robust_bounds.PACKING and search.N >= 3 else None
    if frame is None:
        return False
    X = frame.to_world(frame.Xn)
    if np.all(search.residuals(X) < search.c):
        return False
    search.offer(X)
    return search.best_X is not None


def suspect_bound(search):
    """Generator (:meth:`tritools.solve.robust.TlsSearch.need` requests): a lower bound of f_TLS* (pixels^2) by
    the suspect-set cover (module docstring); 0.0 where the stage does not apply.  The pairs' estimates (two-view
    fits, rarely good TLS candidates) are not screened here: they stay queued for the full search, if it runs."""
    N = search.N
    if N < 3:
        return 0.0
    if search.best_X is None and search.bounds.frame() is not None:     # all views not verified: the parent's
        frame = search.bounds.frame()                                    # L2 estimate (its normalisation's)
        search.offer(frame.to_world(frame.Xn))
    O = yield from _suspects(search)
    if O is None:
        return 0.0
    return (yield from cover(search, O))


def cover_bound(search):
    """Generator: the cover bound (module docstring) with O the best candidate's outlier views, of any number
    (review 6, finding F5: long tracks with many wrong matches, after the pairs and the local optimisation found
    the candidate); 0.0 where O is empty, already covered, or leaves fewer than two views.  W = V - O is verified
    first (its full treatment if that does not certify: it is the best inlier set, whose leaf any certificate
    needs)."""
    O = frozenset(range(search.N)) - search.best_S
    if not O or search.N - len(O) < 2 or O in search.covered or search.deadline.expired:
        return 0.0
    W = search.best_S
    yield from search.verify_first(W)
    if not search.bounds.known(W):
        yield from search.need([W])
    lb = yield from cover(search, O)
    r = search.residuals(search.best_X) / search.c
    far = frozenset(j for j in O if not r[j] < AMBIGUOUS)     # the clear outliers (nan / inf: far)
    if search.meets(lb) or not far or far == O or far in search.covered:
        return lb
    # a view just over its threshold would be a suspect whose node {j} never prunes: it stays with W - far,
    # whose leave-one-out / group bound charges it (its term c_j^2 + L2LB(W - far - j), the best inlier set)
    lb = max(lb, (yield from cover(search, far)))
    if search.meets(lb) or len(O - far) > MAX_SUSPECTS:
        return lb
    return max(lb, (yield from _near_cover(search, far, O - far)))


def _near_cover(search, far: frozenset, near: frozenset):
    """Generator: the cover with the clear outliers ``far`` and the views ``near`` just over their thresholds at the
    best candidate (S* = V - far - near its inlier set): every X keeps some j of far an inlier (node {j}), or has
    far and near all outliers (c^2(far + near) + TLS*(S*)), or far all outliers and some a of near an inlier
    (c^2(far) + the group bound of V - far over the X that keep a, :func:`tritools.solve.robust_loo.kept_bound`)."""
    inside = yield from _inside(search, far)
    if not search.meets(inside):
        return 0.0
    S = frozenset(range(search.N)) - far - near
    both = yield from _outside(search, S, float(np.sum(search.c2[sorted(far | near)])))
    if not search.meets(both):
        return 0.0
    c2_far = float(np.sum(search.c2[sorted(far)]))
    kept = []
    for a in sorted(near):
        kept.append((yield from kept_bound(search, S | near, frozenset((a,)), c2_far)))
        if not search.meets(kept[-1]):
            return 0.0
    return min([inside, both] + kept)


def _inside(search, O: frozenset):
    """Generator: min_{j in O} LB(node {j}) (module docstring), from the view pairs holding j (the first
    :data:`PAIRS_FIRST` partners, W's most confident inliers, then the rest where those do not prune)."""
    W = frozenset(range(search.N)) - O
    r = search.residuals(search.best_X) / search.c             # partners: W's most confident inliers first
    order = sorted(W, key=lambda u: (r[u] if np.isfinite(r[u]) else np.inf, u)) + sorted(O)
    inside = 0.0
    for part in (order[:PAIRS_FIRST], order[PAIRS_FIRST:]):
        if search.deadline.expired:          # |O| (N - 1) pairs: not even built past the deadline (0 is valid)
            return inside
        yield from search.verify_first(*[frozenset((j, u)) for j in sorted(O) for u in part if u != j])
        nodes = _inlier_nodes(search, O)
        inside = min(nodes.values()) if nodes is not None else 0.0
        if search.meets(inside):
            break
    if search.meets(inside) or len(O) > MAX_SUSPECTS or nodes is None:
        return inside
    return max(inside, (yield from _kept_nodes(search, nodes)))


def _kept_nodes(search, nodes: dict):
    """Generator: min_{j} LB(node {j}) over the suspects' pair bounds ``nodes`` (j -> bound), each one that does not
    meet raised by the group bound of all views over the X that keep j an inlier
    (:func:`tritools.solve.robust_loo.kept_bound`: min(L2LB(V), the group terms that leave j in)).  The pairs alone
    cannot bound a suspect whose own threshold is far below the others' (review 8 F4: one view at c_j = half its L2
    residual on a clean 30-view track): keeping j in costs the L2 of all views, which the pairs do not see; 0 where
    the deadline cut it short."""
    V = frozenset(range(search.N))
    best = math.inf
    for j, node in sorted(nodes.items()):
        if search.deadline.expired:
            return 0.0
        if not search.meets(node):
            node = max(node, (yield from kept_bound(search, V, frozenset((j,)), 0.0)))
        best = min(best, node)
        if not search.meets(best):
            break
    return best


def _inlier_nodes(search, O: frozenset) -> dict | None:
    """{j: LB(node {j})} for the suspects O; None once the search's deadline has passed (each node bound looks at
    the pairs of j: ~N^2 work over the suspects, seconds at N = 200 with many suspects, review 8 F1)."""
    nodes = {}
    for j in sorted(O):
        if search.deadline.expired:
            return None
        nodes[j] = _inlier_node(search, j)
    return nodes


def cover(search, O: frozenset):
    """Generator: min(min_{j in O} LB(node {j}), c^2(O) + TLS*(V - O)) (module docstring) for the suspects O."""
    search.covered.add(O)
    inside = yield from _inside(search, O)
    if not search.meets(inside):
        return 0.0
    W = frozenset(range(search.N)) - O
    c2_out = float(np.sum(search.c2[sorted(O)]))
    outside = yield from _outside(search, W, c2_out)
    return _told(search, O, min(inside, outside))


def _told(search, O: frozenset, lb: float) -> float:
    """``lb``, with the cover's split kept on the search (``cover_splits``: O -> (O as a mask, None, None, None,
    nodes); ``cover_keys``: O -> lb_out) for the report's lowering (:func:`tritools.solve.robust_split._split_lower`).

    Every set S holding a view j of O has a term L2*(S) + c^2(V - S) of at least min(g_j, the term of S - j), where
    g_j = min_{s in [0, c_j^2]} s + sum_{u != j} min(c_u^2, max(0, a_u - s)) with a_u <= L2*({j, u}) (s = d_j^2 at the
    minimiser of S: where s <= c_j^2 each u in S pays d_u^2 >= a_u - s and each u outside pays c_u^2; where s > c_j^2
    the term is at least c_j^2 + L2*(S - j) + c^2(V - S), the term of S - j) -- on any data, so on the caller's too,
    with a_u the pair bounds lowered by their own round-off (``nodes``: (c_j^2, a (N - 1,), c_u^2 (N - 1,)) per j;
    the report lowers each a_u, the bound is monotone in them).  Down the chain a set without O's views remains,
    whose term holds only V - O's data and is at least any valid bound of f*_TLS (the search's, whatever gave it),
    lowered by V - O's round-off.  ``lb_out`` = min_j g_j on the search's data (which cover to report)."""
    mask = np.zeros(search.N, bool)
    mask[sorted(O)] = True
    nodes, lb_out = [], math.inf
    for j in sorted(O):
        U, a = _pair_bounds(search, j)
        nodes.append((float(search.c2[j]), a[U], search.c2[U].copy()))
        lb_out = min(lb_out, search.bound_uncapped(frozenset((j,)), 0.0, U, 0.0, a))
    search.cover_splits[O] = Split(mask, parts=(None, None, None, tuple(nodes)))   # (lb_out: not valid as one number)
    search.cover_keys[O] = lb_out
    return lb


def cover_split(search) -> Split | None:
    """The split of the search's bound by one of its covers (:func:`_told`; valid with any bound of the search): the
    cover of the best inlier set's outliers, else the one whose nodes are bounded highest; None without a cover."""
    if not search.cover_splits:
        return None
    best = frozenset(range(search.N)) - frozenset(search.best_S)
    return search.cover_splits.get(best) or search.cover_splits[max(search.cover_keys, key=search.cover_keys.get)]


def _suspects(search):
    """Generator: the suspect set O (module docstring), or None.  O starts as the best candidate's outlier views,
    or, where that holds more than :data:`MAX_SUSPECTS` (a wrong match pulls the L2 estimate of all views away
    from every view), as its worst view by d_i / c_i; each round verifies W = V - O, offers W's estimate and
    takes the best candidate's outliers if they are few, else adds W's worst view by its estimate (verified or
    only polished, ``SubsetBounds.trial``).  O is returned once the best candidate's outliers are exactly O.  Where
    the rounds find none and N <= :data:`SMALL_N`, every fit of V - j is offered and O read off the best one."""
    full = frozenset(range(search.N))
    if search.best_X is None:
        return None
    O = yield from _refit(search, full - search.best_S)
    if O is None and search.N <= SMALL_N:                    # every leave-one-out fit (a few small rows)
        drops = [full - {j} for j in range(search.N)]
        yield from search.verify_first(*drops)
        for W in drops:
            search.offer(search.bounds.estimate(W) if search.bounds.known(W) else search.bounds.trial.get(W))
        O = full - search.best_S
        if 0 < len(O) <= MAX_SUSPECTS and search.bounds.known(full - O):
            return O
        return None
    return O


def _refit(search, O: frozenset):
    """Generator: :func:`_suspects`' rounds from the outlier set O of the best candidate."""
    full = frozenset(range(search.N))
    if len(O) > MAX_SUSPECTS:
        O = frozenset((_worst(search, search.best_X, full),))
    for _ in range(ROUNDS):
        if not O or len(O) > MAX_SUSPECTS or search.N - len(O) < 2:
            return None
        W = full - O
        yield from search.verify_first(W)
        if search.bounds.known(W):
            search.offer(search.bounds.estimate(W))
        now = full - search.best_S
        if now == O and search.bounds.known(W):
            return O
        X = search.bounds.estimate(W) if search.bounds.known(W) else search.bounds.trial.get(W)
        if 0 < len(now) <= MAX_SUSPECTS:
            O = now
        elif X is not None:
            O = O | {_worst(search, X, W)}
        else:
            return None
    return None


def _worst(search, X, views: frozenset) -> int:
    """The view of ``views`` with the largest d_i(X) / c_i (an undefined projection counts as infinite)."""
    r = search.residuals(X) / search.c
    idx = sorted(views)
    return int(idx[int(np.argmax(np.where(np.isnan(r[idx]), np.inf, r[idx])))])


def _inlier_node(search, j: int) -> float:
    """LB(node I = {j}) (module docstring) from the cached pair bounds L2LB({j, u}) (unknown: 0)."""
    U, a = _pair_bounds(search, j)
    return search._bound(frozenset((j,)), 0.0, U, 0.0, a)


def _pair_bounds(search, j: int) -> tuple[list, np.ndarray]:
    """(the other views U, a (N,)): a_u the cached pair bound L2LB({j, u}) (unknown: 0; a_j = 0)."""
    a = np.zeros(search.N)
    for u in range(search.N):
        P = frozenset((j, u))
        if u != j and search.bounds.known(P):
            a[u] = search.bounds.bound(P)
    return [u for u in range(search.N) if u != j], a


def _outside(search, W: frozenset, c2_out: float):
    """Generator: c^2(O) + a lower bound of TLS*(W) (module docstring): the root bound of W, else its
    leave-one-out bound where L2LB(W) alone would meet the best value."""
    b = search.bounds
    c2 = search.c2
    lw = b.bound(W) if b.known(W) else 0.0
    root = (c2_out + min(lw, float(np.min(c2[sorted(W)])))) * ROUND_DOWN
    if search.meets(root) or len(W) < 3 or not search.meets((c2_out + lw) * ROUND_DOWN):
        return root
    return (yield from leave_one_out(search, W, c2_out))
