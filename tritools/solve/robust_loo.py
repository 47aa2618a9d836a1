"""The leave-one-out bound of the TLS search with its sub-bounds from two halves first.

For a view set W whose best candidate keeps every view of W an inlier (a clean track, or the inliers W = V - O of
the suspect stage, :mod:`tritools.solve.robust_suspects`), an X with an outlier k in W pays c_k^2 plus at least the
root bound of W - k, so (the argument of :meth:`tritools.solve.robust.TlsSearch.leave_one_out_bound`)

    TLS*(W) >= min( L2LB(W), min_{k in W} [ c_k^2 + min(L2*(W - k), min_{i in W - k} c_i^2) ] ).

Computing L2LB(W - k) for every k costs |W| sub-problems of |W| - 1 views.  Split W into two disjoint halves A and
B; by superadditivity (:mod:`tritools.solve.robust_bounds`: every term of the sum over W - k is a term of exactly
one part, and each part's sum is at least its own minimum)

    L2*(W - k) >= L2*(A - k) + L2*(B)   (k in A),        L2*(W - k) >= L2*(A) + L2*(B - k)   (k in B),

which needs A, B and the |W| sets A - k, B - k of about |W| / 2 - 1 views: the verification cost of a subset grows
with the cube of its size, so these are several times cheaper than the |W| sets W - k.  The split loses about three
degrees of freedom of the fit (the two halves are fitted separately), which matters only where the term is tight;
the sets W - k whose split term does not meet the best value are then verified themselves, and the larger bound
kept.  Sub-bounds the verification does not certify count 0; the result is rounded down.

Groups (review 6, finding F5).  The term above caps what an X with an outlier k pays on the rest at min c^2 (the
root bound of W - k): once L2*(W) exceeds about 2 min c^2 -- long tracks, thresholds a few times the noise -- it
cannot reach L2LB(W).  The *group bound* charges every outlier of W instead.  Split W into disjoint groups
G_1, ..., G_m.  For an X with outlier set K = W - T(X) (K != {}), f_W(X) = sum_g f_G(X) with
f_G(X) = sum_{i in G} min(d_i(X)^2, c_i^2), and for each group

    K n G = {}:        f_G(X) = sum_G d_i^2                    >= in_G  = L2LB(G),
    K n G = {k}:       f_G(X) = c_k^2 + sum_{G - k} d_i^2      >= c_k^2 + L2LB(G - k),
    |K n G| >= 2:      f_G(X) >= c^2(K n G)                    >= the two smallest c_i^2 of G,

so with e_G = min(min_k [c_k^2 + L2LB(G - k)], two smallest c_i^2 of G) (a group holding an outlier) and the
nonempty set H of the groups K meets (the views outside the groups of H are all inliers of X),

    TLS*(W) >= min( L2LB(W),  min_{H != {}} [ sum_{g in H} e_g + max(L2LB(W - G_H), sum_{g not in H} in_g) ] ),

G_H the union of the groups of H; where one group holds exactly one outlier k, also c_k^2 + L2LB(W - k) (asked
for the views k whose term the groups leave open).  The complements W - G_H are asked for |H| = 1, 2, ..., h
while there are at most :data:`MAX_COMPLEMENTS` of them (m = 4: h = 4; m = 8: h = 3; m = 16: h = 2); for
|H| > h the sum of in_g stands, and the minimum over those H takes every group with e_g < in_g, completed to
h + 1 groups by the smallest e_g - in_g.  It needs the m groups, the |W| sets G - k of about |W| / m views and
the complements, asked level by level while the bound does not meet the best value.  Splitting costs about three
squared noise units per group (each group fits its own point), so m = 2 comes first (the halves above: the same
sub-bounds, and never weaker than their split term), then m = 4, 8, 16 where that does not meet the best value
(:func:`group_counts`: fewer groups lose less to the split, more groups keep each group's cost below 2 min c^2,
where a second outlier in it is charged).
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from .robust_bounds import ROUND_DOWN

__all__ = ["leave_one_out", "halves", "groups", "group_bound", "kept_bound", "group_counts", "MAX_GROUPS",
           "MAX_COMPLEMENTS", "GROUPS"]

#: the group bound tries at most this many groups (module docstring)
MAX_GROUPS = 16
#: the group bound asks for the complements W - G_H of the sets H of h hit groups while there are at most this many
MAX_COMPLEMENTS = 128
#: False: no group bound, the halves' leave-one-out term only (the tests compare the two)
GROUPS = True


def halves(W: frozenset) -> tuple:
    """(A, B): W split into two disjoint halves (alternate views of the sorted set)."""
    idx = sorted(W)
    return frozenset(idx[::2]), frozenset(idx[1::2])


def leave_one_out(search, W: frozenset, c2_out: float):
    """Generator (:meth:`tritools.solve.robust.TlsSearch.need` requests): c2_out + the leave-one-out lower bound
    of TLS*(W) (module docstring), rounded down; L2LB(W) is the cached bound of W (0 if unknown).  With
    :data:`GROUPS` the group bound (halves first, then more groups), whose single-outlier terms take L2LB(W - k)
    where the groups do not suffice; else the halves' leave-one-out terms."""
    b = search.bounds
    lw = b.bound(W) if b.known(W) else 0.0
    A, B = halves(W)
    yield from search.verify_first(A, B, *[A - {k} for k in sorted(A)], *[B - {k} for k in sorted(B)])
    if not GROUPS:
        return (yield from _halves_only(search, W, c2_out, lw, A, B))
    parts, grouped = (A, B), (c2_out + min(lw, _groups_term(search, (A, B), W))) * ROUND_DOWN
    for m in group_counts(search, W):
        if search.meets(grouped) or search.deadline.expired:    # past the limit: the bound so far (valid)
            return grouped
        bound, more = yield from _group_bound(search, W, c2_out, m)
        if bound > grouped:
            parts, grouped = more, bound
    if search.meets(grouped):
        return grouped
    weak = [k for k in sorted(W) if not search.meets(c2_out + _single(search, parts, W, k))]
    if weak:                                         # the single-outlier terms the groups leave open: W - k itself
        yield from search.verify_first(*[W - {k} for k in weak])
        search.offer_new()
    return max(grouped, (c2_out + min(lw, _groups_term(search, parts, W))) * ROUND_DOWN)


def _halves_only(search, W: frozenset, c2_out: float, lw: float, A: frozenset, B: frozenset):
    """Generator: the halves' leave-one-out bound alone (no groups; the tests compare the two)."""
    b = search.bounds
    sub = {k: _split(b, A - {k}, B) if k in A else _split(b, A, B - {k}) for k in W}
    weak = [k for k in sorted(W) if not search.meets(_term(search, W, k, sub[k], c2_out))]
    if weak:
        yield from search.verify_first(*[W - {k} for k in weak])
        search.offer_new()
        for k in weak:
            if b.known(W - {k}):
                sub[k] = max(sub[k], b.bound(W - {k}))
    terms = [c2_out + lw] + [_term(search, W, k, sub[k], c2_out) for k in sorted(W)]
    return min(terms) * ROUND_DOWN


def groups(search, W: frozenset, m: int) -> tuple:
    """W split into m disjoint groups of about equal cost at the best candidate: the views by decreasing
    d_i^2 (capped at c_i^2), dealt in a snake order (0, 1, ..., m - 1, m - 1, ..., 0, ...)."""
    d2 = np.minimum(search.residuals(search.best_X) ** 2, search.c2) if search.best_X is not None else \
        np.zeros(search.N)
    idx = sorted(W, key=lambda i: (-d2[i] if np.isfinite(d2[i]) else -np.inf, i))
    out = [[] for _ in range(m)]
    for r, i in enumerate(idx):
        lap, pos = divmod(r, m)
        out[pos if lap % 2 == 0 else m - 1 - pos].append(i)
    return tuple(frozenset(g) for g in out if g)


def group_counts(search, W: frozenset) -> list:
    """The group counts m > 2 that :func:`group_bound` tries, in order (module docstring): 4, 8, ... while the
    groups keep at least three views, up to :data:`MAX_GROUPS`, and only where the best candidate's cost on W,
    sum of min(d_i^2, c_i^2), exceeds the smallest c_i^2 of W (else the halves, m = 2, are the right split)."""
    if search.best_X is None or len(W) < 12:
        return []
    idx = sorted(W)
    d2 = np.minimum(search.residuals(search.best_X)[idx] ** 2, search.c2[idx])
    c2_min = float(np.min(search.c2[idx]))
    if not (np.all(np.isfinite(d2)) and np.isfinite(c2_min) and float(np.sum(d2)) > c2_min):
        return []
    return [m for m in (4, 8, 16) if m <= MAX_GROUPS and 3 * m <= len(W)]


def group_bound(search, W: frozenset, c2_out: float, m: int):
    """Generator (:meth:`tritools.solve.robust.TlsSearch.need` requests): c2_out + the group bound of TLS*(W) with
    m groups (module docstring), rounded down; verification only (unknown sub-bounds count 0)."""
    bound, _ = yield from _group_bound(search, W, c2_out, m)
    return bound


def _group_bound(search, W: frozenset, c2_out: float, m: int, keep: frozenset = frozenset()):
    """Generator: (:func:`group_bound`, the groups it used); the views of ``keep`` never outliers
    (:func:`kept_bound`)."""
    b = search.bounds
    parts = groups(search, W, m)
    yield from search.verify_first(*parts, *[G - {k} for G in parts for k in sorted(G - keep)],
                                   *([W - G for G in parts] if m > 2 else []))
    search.offer_new()
    lw = b.bound(W) if b.known(W) else 0.0
    bound = (c2_out + min(lw, _groups_term(search, parts, W, keep))) * ROUND_DOWN
    for h in range(2, _most_hit(m) + 1):           # h groups hit: the complements of every h groups
        if search.meets(bound) or h >= m - 1 or search.deadline.expired:
            break
        yield from search.verify_first(*[W - frozenset().union(*H) for H in itertools.combinations(parts, h)])
        bound = max(bound, (c2_out + min(lw, _groups_term(search, parts, W, keep))) * ROUND_DOWN)
    return bound, parts


def _most_hit(m: int) -> int:
    """The largest number h of hit groups whose complements are asked (:data:`MAX_COMPLEMENTS` sets at most)."""
    h = 1
    while h < m and math.comb(m, h + 1) <= MAX_COMPLEMENTS:
        h += 1
    return h


def _rest(b, parts: tuple, inside: list, W, g: int) -> float:
    """A lower bound of L2*(W - G_g): the larger of its cached bound and the sum of the other groups' bounds."""
    rest = sum(inside[h] for h in range(len(parts)) if h != g)
    if W is not None and b.known(W - parts[g]):
        rest = max(rest, b.bound(W - parts[g]))
    return rest


def _single(search, parts: tuple, W, k: int) -> float:
    """The bound of an X whose only outlier in W is k (not rounded): c_k^2 + the larger of L2LB(G - k) +
    L2LB(W - G) (G the group of k, :func:`_rest`) and L2LB(W - k) where cached."""
    b = search.bounds
    inside = [b.bound(G) if b.known(G) else 0.0 for G in parts]
    g = next(h for h, G in enumerate(parts) if k in G)
    G = parts[g]
    split = (b.bound(G - {k}) if b.known(G - {k}) else 0.0) + _rest(b, parts, inside, W, g)
    whole = b.bound(W - {k}) if W is not None and b.known(W - {k}) else 0.0
    return float(search.c2[k]) + max(split, whole)


def _groups_term(search, parts: tuple, W: frozenset | None = None, keep: frozenset = frozenset()) -> float:
    """min over the nonempty sets H of groups of the bound of an X whose outliers in W meet exactly the groups H
    (module docstring), from the cached bounds (unknown: 0); not rounded.  One group hit by one outlier k:
    :func:`_single`; one or two groups hit: sum_{g in H} e_g plus the larger of L2LB(W - union of H) (the
    complement, where cached) and sum of in_g over the other groups; three or more: sum_{g in H} e_g +
    sum_{g not in H} in_g, smallest for the groups with e_g < in_g, completed to three groups by the smallest
    e_g - in_g.  The views of ``keep`` are inliers of every X considered (never in K)."""
    b = search.bounds
    c2 = search.c2
    inside, hit, terms = [], [], []
    for G in parts:
        inside.append(b.bound(G) if b.known(G) else 0.0)
        free = sorted(G - keep)                     # the views of G that may be outliers
        one = min((float(c2[k]) + (b.bound(G - {k}) if b.known(G - {k}) else 0.0) for k in free), default=np.inf)
        hit.append(min(one, float(np.sum(np.sort(c2[free])[:2])) if len(free) >= 2 else np.inf))
    m = len(parts)
    for g, G in enumerate(parts):                   # one group hit by one outlier k: c_k^2 + a bound of L2*(W - k)
        free = sorted(G - keep)
        rest = _rest(b, parts, inside, W, g)
        ones = [float(c2[k]) + max((b.bound(G - {k}) if b.known(G - {k}) else 0.0) + rest,
                                   b.bound(W - {k}) if W is not None and b.known(W - {k}) else 0.0) for k in free]
        two = float(np.sum(np.sort(c2[free])[:2])) if len(free) >= 2 else np.inf
        terms.append(min(ones + [two + rest]))          # two or more outliers in G: c^2 of two of them at least
    top = max(2, min(_most_hit(m), m))
    for H in itertools.chain.from_iterable(itertools.combinations(range(m), h) for h in range(2, top + 1)):
        rest = sum(inside[g] for g in range(m) if g not in H)
        union = frozenset().union(*(parts[g] for g in H))
        if W is not None and b.known(W - union):
            rest = max(rest, b.bound(W - union))
        terms.append(sum(hit[g] for g in H) + rest)
    if m > top:
        with np.errstate(invalid="ignore"):
            delta = np.array(hit) - np.array(inside)      # only to choose H (inf - finite = inf)
        order = [int(g) for g in np.argsort(delta, kind="stable")]
        H = {g for g in order if delta[g] < 0} | set(order[:top + 1])
        terms.append(sum(hit[g] if g in H else inside[g] for g in range(m)))     # sums of terms >= 0
    return float(min(terms))


def kept_bound(search, W: frozenset, keep: frozenset, c2_out: float):
    """Generator: c2_out + a lower bound of min f_W(X) over the X that keep every view of ``keep`` an inlier:
    min(L2LB(W), the group terms with K disjoint from ``keep``) (module docstring), with m = 2 and then the
    groups of :func:`group_counts`, rounded down; verification only."""
    yield from search.verify_first(W)
    best = 0.0
    for m in [2] + group_counts(search, W):
        bound, _ = yield from _group_bound(search, W, c2_out, m, keep)
        best = max(best, bound)
        if search.meets(best):
            break
    return best


def _split(b, P: frozenset, Q: frozenset) -> float:
    """L2LB(P) + L2LB(Q) (unknown: 0), rounded down: a lower bound of L2*(P + Q) for disjoint P, Q."""
    return ((b.bound(P) if b.known(P) else 0.0) + (b.bound(Q) if b.known(Q) else 0.0)) * ROUND_DOWN


def _term(search, W: frozenset, k: int, l2_sub: float, c2_out: float) -> float:
    """c2_out + c_k^2 + min(l2_sub, min_{i in W - k} c_i^2): the bound of the X with k an outlier."""
    rest = float(np.min(search.c2[sorted(W - {k})]))
    return c2_out + search.c2[k] + min(l2_sub, rest)
