"""When the TLS search stops early because a certificate is out of its reach (review 6, finding F6).

A leaf of the branch and bound of :mod:`tritools.solve.robust` fixes every view: inliers I, outliers O = V - I.  Its
bound is

    LB(leaf I) = c^2(O) + L2LB(I)        (L2LB(I) <= L2*(I), the certified L2 lower bound of the sub-problem I),

and the reported lower bound of f_TLS* is at most the bound of every leaf the search neither pruned nor left
open (module docstring of :mod:`tritools.solve.robust`: the minimum of UB and of the bounds of the nodes pruned
below UB or left open).  The search raises a leaf's bound in three ways only: inherited bounds of subsets of I
(monotonicity), a split L2*(I) >= L2*(T) + L2*(I - T) (:meth:`tritools.solve.robust_bounds.SubsetBounds.split_bound`)
and the full degree plan on I (:meth:`~tritools.solve.robust_bounds.SubsetBounds.strengthen`).  Once all three are
spent the leaf's bound is final: L2LB(I) is *exhausted* (``SubsetBounds.exhausted``: the full plan ended
``not_certified``, not at a time or memory limit, or Corollary 1 provably cannot raise it, coplanar centres,
:func:`tritools.solve.coplanar.subset_futile`).

The rule.  When a leaf I with an exhausted bound does not meet the best value UB under the certificate rule
(``Tolerances.certified`` at the search's scale), then with the current UB the branch and bound cannot certify,
whatever it does next: its lower bound stays at or below LB(leaf I) < UB - tol (the stages before it -- the root,
leave-one-out and cover bounds -- did not meet UB either, or there would be no search).  A certificate would need a
candidate better than UB by more than the rest of the gap -- down to within the tolerance of a bound that the L2
path's own full plan on I could not raise to its own estimate.  The search stops there with status
``not_certified``, its valid bounds (the leaf's bound is one of them), the best estimate and its inlier set, and a
message naming the leaf.  The leaf of the best candidate's inlier set S* holds the best candidate itself, so it
cannot be pruned by exceeding UB, only by meeting it: :func:`settle_best_set` examines it first, right after the
candidate of all views, with the full plan if its light bound does not meet UB (for S* = V within the search's
deadline, as the plain call, not :data:`~tritools.solve.robust_bounds.SUB_TIME_LIMIT`), so that a problem whose
own L2 path gives up costs about one plain L2 call, not a search over its subsets.  Where it fires there with S* = V the
leave-one-out bound is skipped (it is at most L2LB(V)); the suspect stage, the pairs, the local optimisation and the
cover of the candidate's outliers still run (they may change the candidate, or certify by another route), and the
rule is applied again before the search (:func:`blocks`).  Before the search the rule takes S*'s leaf bound with
the cached bounds of S* and its subsets (what the nodes on S*'s path inherit), not the lookahead sums of
increments L2LB(I + u) - L2LB(I) those nodes also use: a certificate through them alone -- a sum of sub-bounds
meeting UB within the tolerance where S*'s own full plan does not -- is possible in principle; no case of the
campaigns showed one (benchmarks/RESULTS.md: robust protocol cells and mixed-region campaigns, no certificate
lost).  In the search (:func:`leaf_futile`) the leaf has been reached, so the search's bound holds it.

:data:`ENABLED` = False turns the rule off (the tests compare the two).
"""
from __future__ import annotations

import math

import numpy as np

from . import robust_bounds
from .coplanar import COPLANAR_BUDGET_NAME
from .robust_bounds import ROUND_DOWN

__all__ = ["ENABLED", "FUTILE", "blocks", "leaf_bound", "leaf_futile", "settle_best_set", "futile_message"]

#: False: the search never stops for futility (the tests compare the two).
ENABLED = True
#: the search's ``stopped`` reason when the rule fires.
FUTILE = "certification out of reach"


def leaf_bound(search, I: frozenset) -> float:
    """LB(leaf I) = c^2(V - I) + L2LB(I), L2LB(I) the largest cached bound of I and of its subsets (monotonicity:
    what the nodes on I's path inherit; 0 when none is known or |I| <= 1), rounded down."""
    out = [v for v in range(search.N) if v not in I]
    lb = search.bounds.inherited(I)
    return float((float(np.sum(search.c2[out])) + lb) * ROUND_DOWN)


def leaf_futile(search, I: frozenset, lb: float) -> bool:
    """Does the leaf I, whose bound ``lb`` the search has just taken, stop the search (module docstring)?  True when
    the rule is on, L2LB(I) is exhausted, the deadline has not passed (then the time limit is the reason) and
    ``lb`` does not meet UB."""
    if not ENABLED or len(I) < 2 or I not in search.bounds.exhausted or search.deadline.expired:
        return False
    if search.meets(lb):
        return False
    search.futile_leaf = (I, lb)
    return True


def settle_best_set(search) -> bool:
    """Whether the leaf of the best candidate's inlier set S* stops the search before it starts (module docstring):
    where S*'s bound came from a light (degree-2) solve that did not certify and its leaf bound does not meet UB,
    S* is strengthened first (split, then the full degree plan: the step the search would take at that leaf
    anyway), and the rule is applied to the result."""
    if not ENABLED or search.best_X is None:
        return False
    S = search.best_S
    if len(S) < 2 or not search.bounds.known(S) or search.deadline.expired:
        return False
    lb = leaf_bound(search, S)
    if search.meets(lb):
        return False
    c2_out = float(np.sum(search.c2[[v for v in range(search.N) if v not in S]]))
    whole = len(S) == search.N                  # the whole problem: its full plan gets the deadline, as a plain call
    limit = math.inf if whole else robust_bounds.SUB_TIME_LIMIT
    if S in search.bounds.weak and search.bounds.strengthen(S, (search.best_f - c2_out) / ROUND_DOWN, limit):
        search.offer_new()
        if search.best_S != S:                  # the full solve's estimate changed the best inlier set
            return False
        lb = leaf_bound(search, S)
    return leaf_futile(search, S, lb)


def blocks(search) -> bool:
    """Before the branch and bound: does a leaf stop it (the leaf that fired the rule during the candidate stage,
    if it still does not meet the best value, which may have come down since; else :func:`settle_best_set`)?"""
    if search.futile_leaf is not None and leaf_futile(search, *search.futile_leaf):
        return True
    search.futile_leaf = None
    return settle_best_set(search)


def futile_message(search) -> str:
    """The end of the result's message when the rule stopped the search."""
    leaf = getattr(search, "futile_leaf", None)
    if leaf is None:
        return f"stopped: {FUTILE}"
    on_ceiling = leaf[0] in getattr(search.bounds, "on_ceiling", ())
    ceiling = f"; its bound sits on the {COPLANAR_BUDGET_NAME}" if on_ceiling else ""
    return (f"stopped: {FUTILE} (the leaf of the inlier set of {len(leaf[0])} views keeps the bound {leaf[1]:.6g} "
            f"px^2 after the full degree plan on its L2 sub-problem, below the best value {search.best_f:.6g} px^2 "
            f"by more than the tolerance{ceiling})")
