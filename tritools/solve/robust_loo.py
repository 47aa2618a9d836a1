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
"""
from __future__ import annotations

import numpy as np

from .robust_bounds import ROUND_DOWN

__all__ = ["leave_one_out", "halves"]


def halves(W: frozenset) -> tuple:
    """(A, B): W split into two disjoint halves (alternate views of the sorted set)."""
    idx = sorted(W)
    return frozenset(idx[::2]), frozenset(idx[1::2])


def leave_one_out(search, W: frozenset, c2_out: float):
    """Generator (:meth:`tritools.solve.robust.TlsSearch.need` requests): c2_out + the leave-one-out lower bound
    of TLS*(W) (module docstring), rounded down; L2LB(W) is the cached bound of W (0 if unknown)."""
    b = search.bounds
    lw = b.bound(W) if b.known(W) else 0.0
    A, B = halves(W)
    yield from search.verify_first(A, B, *[A - {k} for k in sorted(A)], *[B - {k} for k in sorted(B)])
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


def _split(b, P: frozenset, Q: frozenset) -> float:
    """L2LB(P) + L2LB(Q) (unknown: 0), rounded down: a lower bound of L2*(P + Q) for disjoint P, Q."""
    return ((b.bound(P) if b.known(P) else 0.0) + (b.bound(Q) if b.known(Q) else 0.0)) * ROUND_DOWN


def _term(search, W: frozenset, k: int, l2_sub: float, c2_out: float) -> float:
    """c2_out + c_k^2 + min(l2_sub, min_{i in W - k} c_i^2): the bound of the X with k an outlier."""
    rest = float(np.min(search.c2[sorted(W - {k})]))
    return c2_out + search.c2[k] + min(l2_sub, rest)
