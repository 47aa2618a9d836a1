"""The split of a TLS search's bound by views, for the report's round-off lowering (:mod:`.robust_report`).

f*_TLS = min_S L2*(S) + c^2(V - S), and the L2 problem of a set S holds the data of its own views only: a report
lowers each part of a search's bound by the round-off of its own views' coordinates (:func:`_split_lower`), so a wrong
match far off the image costs only the sets that hold it.  The parts come from an enumeration (:func:`outside_split`:
every set of two views or more has its term; the sets of at most one view are exact) or from a branch and bound's
suspect cover (:func:`tritools.solve.robust_suspects._told`: nodes bounded through their pair bounds,
:func:`_nodes_bound`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .decide import gamma_from_c, gamma_lower, gamma_lower_one
from .robust_subsolve import ROUND_DOWN

__all__ = ["Split", "outside_split", "pair_nodes", "exact_sets_bound"]


class Split(Sequence):
    """A split of a search's bound by views: the sequence (outside (N,) bool, lb_out, lb_in, exact, nodes) of
    :func:`_split_lower`.  ``outside`` is given; the other parts are given (``parts``) or computed from an
    enumeration's ``source`` = (W, terms, c2, lb) on first use (:func:`outside_split`): a report reads them only where
    the plain lowering fails its guard (:func:`_split_needed`), so the stacked enumeration does not pay for them per
    problem."""

    def __init__(self, outside: np.ndarray, parts: tuple | None = None, source: tuple | None = None):
        self.outside, self._parts, self._source = outside, parts, source

    def parts(self) -> tuple:
        """(lb_out, lb_in, exact, nodes)."""
        if self._parts is None:
            self._parts = _enumerated_parts(self.outside, *self._source)
        return self._parts

    def __getitem__(self, i):
        return self.outside if i == 0 else ((self.outside,) + self.parts())[i]

    def __len__(self) -> int:
        return 5


def outside_split(W: np.ndarray, terms, outside, c2=None, lb=None) -> Split | None:
    """The :class:`Split` (outside (N,) bool, lb_out, lb_in, exact, nodes) for the report's lowering
    (:func:`tritools.solve.robust_report.tls_reported`'s ``split``): lb_out the least closed term of the sets ``W``
    (M, N) of at least two views that hold a view ``outside`` (the views left out of the best inlier set; inf for
    none), lb_in the least of those that hold none (inf for none) and ``exact`` the least value of the sets of at most
    one view (:func:`exact_sets_bound` of the squared thresholds ``c2`` (N,); None without them: lb_in and exact then
    stay with the search's bound), and with the sets' L2 bounds ``lb`` (M,) the nodes of the outside views
    (:func:`pair_nodes`; else None), None where no view is outside.  Every set of at least two views must be a row of
    ``W`` (an enumeration's)."""
    outside = np.asarray(outside, bool)
    if not outside.any():
        return None
    return Split(outside, source=(W, terms, c2, lb))


def _enumerated_parts(outside: np.ndarray, W: np.ndarray, terms, c2, lb) -> tuple:
    """(lb_out, lb_in, exact, nodes) of :func:`outside_split`."""
    big = W.sum(axis=1) >= 2
    holds = (W & outside[None]).any(axis=1)
    terms = np.asarray(terms, float)

    def least(rows) -> float:
        return float(np.min(terms[rows])) if rows.any() else math.inf

    exact = None if c2 is None else float(exact_sets_bound(np.asarray(c2, float)[None])[0])
    nodes = None if c2 is None or lb is None else pair_nodes(W, lb, outside, c2)
    return least(holds & big), least(~holds & big), exact, nodes


def pair_nodes(W: np.ndarray, lb, outside: np.ndarray, c2) -> tuple:
    """The nodes {j} of the ``outside`` views for :func:`_nodes_bound`: (c_j^2, a (N - 1,), c_u^2 (N - 1,)) with a_u the
    L2 bound of the pair {j, u} among the sets ``W`` (M, N) and their bounds ``lb`` (M,) (0 where it has none)."""
    W = np.asarray(W, bool)
    lb = np.asarray(lb, float)
    c2 = np.asarray(c2, float)
    N = W.shape[1]
    pair = np.full((N, N), 0.0)
    rows = np.nonzero(W.sum(axis=1) == 2)[0]
    for r in rows:
        i, j = np.nonzero(W[r])[0]
        b = lb[r] if np.isfinite(lb[r]) and lb[r] > 0 else 0.0
        pair[i, j] = pair[j, i] = b
    out = []
    for j in np.nonzero(outside)[0]:
        U = np.array([u for u in range(N) if u != j])
        out.append((float(c2[j]), pair[j, U].copy(), c2[U].copy()))
    return tuple(out)


def exact_sets_bound(c2: np.ndarray) -> np.ndarray:
    """(P,) the least f_TLS bound of the sets S of at most one view, rounded down: L2*(S) = 0 exactly (no data), so
    the term is c^2(V - S), least at S = {the view of the largest c} (the empty set's c^2(V) is no less); c2 (P, N)
    the squared thresholds (inf where one is inf)."""
    N = c2.shape[1]
    with np.errstate(over="ignore", invalid="ignore"):
        small = np.sum(np.where(np.eye(N, dtype=bool)[None], 0.0, c2[:, None, :]), axis=2)
        return np.minimum(np.min(small, axis=1), np.sum(c2, axis=1)) * ROUND_DOWN


def _split_needed(checked: tuple, certified: bool, split: Split | None) -> bool:
    """Is the split of the search's bound (:func:`_split_lower`) worth its magnitudes: the search certified, the
    bounds lowered by every view's magnitude did not pass the guard, and some view is outside the split?  (Elsewhere
    the plain lowering is reported: valid as well, and what a clean track gets.)"""
    return bool(certified and not checked[2] and split is not None and np.asarray(split[0], bool).any())


def _split_lower(lb: float, drift: float, g_ub: float, N: int, resolution: float, magnitude: float,
                 inner: tuple | None) -> float:
    """gamma_LB of the caller's data from the search's bound ``lb`` (pixels^2) less ``drift``: lowered by the round-off
    of the coordinates' ``magnitude`` (:func:`tritools.solve.decide.gamma_lower_one`), >= 0.

    With ``inner`` = (A_in, lb_out[, lb_in, exact]): f*_TLS = min_S L2*(S) + c^2(V - S), and the L2 problem of a set
    S holds the data of its own views only, so each term moves by the round-off of its own views' coordinates (gamma
    by at most LB_ROUNDOFF_ULPS u (A_S + gamma_UB), as for the L2 path).  ``lb_out`` bounds the terms of the sets
    holding one of the split's views (every view's magnitude, ``magnitude``); the others, whose magnitude is A_in, by
    the search's ``lb`` -- or, given lb_in and exact (:func:`outside_split` of an enumeration, where every set of two
    views or more has its term), the sets of two views or more by lb_in and the sets of at most one view by
    ``exact``, which holds no data and moves by no coordinate's round-off.  gamma_LB is the least lowered part.  A
    wrong match 1e6 px off the image then costs its own sets only, which sit c^2 above UB or more (review 48a F1: it
    lowered every bound by ~u 1e9 px and withdrew the certificate), and a best inlier set of one view at a wrong
    match keeps the exact c^2 of the other (review 49b L1: two views, one 1e8 px off)."""
    def lowered(b: float, A: float | None) -> float:
        if b == math.inf:
            return math.inf
        return max(0.0, gamma_lower_one(gamma_from_c(max(b - drift, 0.0), N, 1.0), g_ub, 1.0, resolution, A))

    if inner is None:
        return lowered(lb, magnitude)
    A_in, lb_out, lb_in, exact, nodes = tuple(inner) + (None,) * (5 - len(inner))
    inside = lowered(lb, A_in) if exact is None else min(lowered(exact, None), lowered(lb_in, A_in))
    out = 0.0 if lb_out is None else lowered(lb_out, magnitude)
    if nodes:                            # the outside views' nodes: their pair bounds lowered one by one
        out = max(out, lowered(_nodes_bound(nodes, N, g_ub, resolution, magnitude), None))
    return min(inside, out)


def _nodes_bound(nodes: tuple, N: int, g_ub: float, resolution: float, magnitude: float) -> float:
    """min_j g_j of a cover's nodes (:func:`tritools.solve.robust_suspects._told`) on the caller's data: each pair
    bound a_u lowered by the round-off of every view's coordinates as an L2 bound (gamma_from_c(a_u) less
    LB_ROUNDOFF_ULPS u (magnitude + max(gamma_UB, its own gamma)), :func:`tritools.solve.decide.gamma_lower`), then
    the node's piecewise-linear minimum (:func:`tritools.solve.robust_nodes.lookahead_bound`), rounded down.  A
    pair holding a wrong match 1e7 px off keeps a_u ~1e14 px^2 >> c^2 after the lowering, so the node's bound stays
    the sum of the thresholds (it is lowered through its pairs, not as a whole: that is what makes it valid)."""
    from .robust_nodes import lookahead_bound

    best = math.inf
    for c2_j, a, c2_u in nodes:
        g = gamma_from_c(np.maximum(a, 0.0), N, 1.0)
        with np.errstate(invalid="ignore", over="ignore"):
            low = gamma_lower(g, np.maximum(g, g_ub), 1.0, resolution, magnitude)
            a_low = np.where(np.isfinite(low), 2.0 * N * low * low * ROUND_DOWN, 0.0)
        best = min(best, lookahead_bound(0.0, c2_j, a_low, c2_u) * ROUND_DOWN)
    return best
