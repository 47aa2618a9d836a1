"""Minimiser candidates of a solved certificate: extracted, polished, checked feasible (strategy step 2 of
:func:`sospoly.minimize`: every point kept here is feasible, so f there is an upper bound of the minimum).

* :func:`candidates_of` -- points read from a solved Positivstellensatz certificate: the Gram kernel and the
  moment matrix of a dense certificate (:mod:`.extraction`), the clique moment matrices joined on their
  overlaps for a sparse one (:mod:`.sparse_extraction`), first and second moments across blocks that lack 1
  or some x_i (term sparsity, Newton polytope; :mod:`.term_extraction`);
* :func:`feasible_points` -- each candidate polished locally (SLSQP with constraints, L-BFGS-B without) and
  kept when its :func:`feasibility_violation`

      max_k max(|g_k(x)| / max(1, ||g_k||_inf),  max(0, -h_k(x)) / max(1, ||h_k||_inf))

  passes :meth:`sospoly.Tolerances.feasible`; sorted by f and merged by :func:`dedupe_points`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..algebra.basis import MonomialIndex
from ..algebra.polynomial import Polynomial
from ..tolerances import Tolerances
from .extraction import Candidate, extract_from_gram, extract_from_moment
from .sparse_extraction import extract_from_clique_moments
from .term_extraction import second_moment_candidates

if TYPE_CHECKING:                     # annotations only: analysis reads a solution, it never solves
    from ..solvers.solve import ProgramSolution

__all__ = ["feasibility_violation", "candidates_of", "feasible_points", "dedupe_points", "support_of",
           "slsqp_equalities"]


def support_of(p: Polynomial) -> np.ndarray:
    """The exponent rows of p's terms (one zero row for the zero polynomial)."""
    return p.exponents() if p.terms else np.zeros((1, p.nvars), np.int64)


def feasibility_violation(point: np.ndarray, eq, ineq) -> float:
    """max over constraints of |g_k| and max(0, -h_k), each relative to max(1, ||coef||_inf)."""
    worst = 0.0
    for g in eq:
        worst = max(worst, abs(g.evaluate(point)) / max(1.0, g.max_abs_coefficient()))
    for h in ineq:
        worst = max(worst, max(0.0, -h.evaluate(point)) / max(1.0, h.max_abs_coefficient()))
    return worst


class _Compiled:
    """Polynomials p_0, ..., p_{m-1} as arrays, for the many evaluations of a local polish: term t of
    p_{which[t]} is coef[t] * prod_j x[cols[t, j]] ** pows[t, j] (padded with x_0 ** 0), so values and
    Jacobian cost a few vectorised operations instead of one Polynomial.evaluate per partial
    derivative and per polynomial."""

    def __init__(self, polys):
        polys = list(polys)
        self.m, self.n = len(polys), polys[0].nvars
        E = np.vstack([support_of(p) for p in polys])
        self.which = np.concatenate([np.full(max(len(p.terms), 1), k) for k, p in enumerate(polys)])
        self.coef = np.concatenate([p.coefficients() if p.terms else np.zeros(1) for p in polys])
        width = max(1, int((E > 0).sum(axis=1).max(initial=0)))
        self.cols = np.zeros((E.shape[0], width), np.int64)
        self.pows = np.zeros((E.shape[0], width), np.int64)
        for t, row in enumerate(E):
            nz = np.nonzero(row)[0]
            self.cols[t, :nz.size], self.pows[t, :nz.size] = nz, row[nz]

    def values(self, x) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):      # a polish step far out: inf / nan, judged there
            terms = self.coef * np.prod(np.asarray(x, float)[self.cols] ** self.pows, axis=1)
            return np.bincount(self.which, weights=terms, minlength=self.m)

    def magnitudes(self, x) -> np.ndarray:
        """sum_t |term_t(x)| per polynomial: the scale of the evaluation's round-off at x."""
        with np.errstate(over="ignore", invalid="ignore"):
            terms = np.abs(self.coef * np.prod(np.asarray(x, float)[self.cols] ** self.pows, axis=1))
            return np.bincount(self.which, weights=terms, minlength=self.m)

    def jacobian(self, x) -> np.ndarray:
        xc = np.asarray(x, float)[self.cols]
        J = np.zeros((self.m, self.n))
        with np.errstate(over="ignore", invalid="ignore"):
            P = xc ** self.pows
            for j in range(self.cols.shape[1]):
                live = self.pows[:, j] > 0
                if not live.any():
                    continue
                others = np.prod(np.delete(P[live], j, axis=1), axis=1)
                d = self.coef[live] * self.pows[live, j] * xc[live, j] ** (self.pows[live, j] - 1) * others
                np.add.at(J, (self.which[live], self.cols[live, j]), d)
        return J


def slsqp_equalities(eq: list, x0: np.ndarray) -> list:
    """At most n of the equality constraints ``eq`` for an SLSQP polish in n variables from x0: all of them when
    there are at most n, else those of the n most independent gradients at x0 (a column-pivoted QR of the
    Jacobian's transpose).  scipy's SLSQP (1.16-1.17) corrupts the heap and kills the process with ~15 or more
    equalities beyond n (review 38a M5: 19 redundant linear equalities in 2 variables); its subproblem is
    overdetermined there anyway.  The polished point is checked against every constraint afterwards
    (:func:`feasible_points`), so a subset loses nothing but the polish of a point it cannot make feasible."""
    n = len(x0)
    if len(eq) <= n:
        return list(eq)
    from scipy.linalg import qr

    J = _Compiled(eq).jacobian(x0)
    J = np.where(np.isfinite(J), J, 0.0)
    pivots = qr(J.T, pivoting=True, mode="r")[1]
    return [eq[k] for k in sorted(pivots[:n].tolist())]


def _polish(f: Polynomial, eq, ineq, x0: np.ndarray) -> np.ndarray | None:
    """Local polish of a candidate (any feasible point gives a valid upper bound): SLSQP with constraints (at most
    n equalities, :func:`slsqp_equalities`), L-BFGS-B without (SLSQP's dense O(n^3) steps cost ~0.1 s each at
    n = 200)."""
    from scipy.optimize import minimize as sp_min

    fc = _Compiled([f])
    eq = slsqp_equalities(list(eq), np.asarray(x0, float))
    cons = [{"type": kind, "fun": c.values, "jac": c.jacobian}
            for kind, c in (("eq", _Compiled(eq) if eq else None), ("ineq", _Compiled(ineq) if ineq else None))
            if c is not None]
    how = dict(method="SLSQP", options={"ftol": 1e-14, "maxiter": 200}) if cons else \
        dict(method="L-BFGS-B", options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 1000})
    try:
        res = sp_min(lambda v: float(fc.values(v)[0]), x0, jac=lambda v: fc.jacobian(v)[0], constraints=cons,
                     **how)
    except Exception:  # noqa: BLE001 - a failed polish just keeps the unpolished candidate
        return None
    return np.asarray(res.x, float) if np.all(np.isfinite(res.x)) else None


def _unit_rows(basis: np.ndarray) -> np.ndarray:
    """Rows of 1, x_1, ..., x_n in ``basis`` (-1 where absent)."""
    n = basis.shape[1]
    units = np.vstack([np.zeros((1, n), np.int64), np.eye(n, dtype=np.int64)])
    return MonomialIndex(basis).find(units, missing_ok=True)


def _first_moments(blocks, n: int) -> np.ndarray | None:
    """The first moments L(x_i) / L(1) read from every (basis, moment matrix) pair holding 1 and x_i
    (averaged; 0 where none does), or None when no block holds the constant.  The starting point for
    blocks that cannot give points by themselves (term sparsity, Newton polytope: a block may lack 1
    or some x_i)."""
    num, cnt, seen = np.zeros(n), np.zeros(n), False
    for B, M in blocks:
        rows = _unit_rows(B)
        if rows[0] < 0 or M is None or not np.all(np.isfinite(M)) or M[rows[0], rows[0]] <= 0:
            continue
        seen = True
        have = rows[1:] >= 0
        num[have] += M[rows[1:][have], rows[0]] / M[rows[0], rows[0]]
        cnt[have] += 1
    return np.where(cnt > 0, num / np.maximum(cnt, 1), 0.0) if seen else None


def candidates_of(psatz, sol: ProgramSolution, tol: Tolerances) -> list[Candidate]:
    """Minimiser candidates: the Gram kernel and moment matrix of a dense certificate; for a sparse one
    the clique moment matrices joined on their overlaps (:mod:`sospoly.analysis.sparse_extraction`) and
    the dense low-degree block's first moments; blocks without 1 and every x_i (term sparsity, Newton
    polytope) give the first moments read across all blocks."""
    u = psatz.u
    names = u.block_names()
    shape = psatz.shape
    n = len(psatz.gens)
    moments, bases, cliques, cands, partial = [], [], [], [], False
    for name, blk, k in zip(names, u.gram.blocks, shape.block_clique or (-1,) * len(names)):
        M = sol.moments.get(name)
        if k < 0 and np.any(_unit_rows(blk.b) < 0):
            partial = True
            continue
        if k < 0 and len(names) == 1 and name in sol.grams:
            cands += extract_from_gram(sol.grams[name], blk.b, tol)
        if M is None:
            continue
        if k < 0:
            cands += [c for c in extract_from_moment(M, blk.b, tol) if c.point.shape == (n,)]
            continue
        cl = np.asarray(shape.cliques[k], np.int64)
        rows = _unit_rows(blk.b[:, cl])
        if rows[0] != 0 or np.any(rows < 0):        # a reduced clique basis without 1 first and every x_i
            partial = True
            continue
        moments.append(M)
        bases.append(blk.b[:, cl])
        cliques.append(tuple(int(i) for i in cl))
    if moments:
        for p in extract_from_clique_moments(moments, bases, cliques, n, tol, greedy=True):
            cands.append(Candidate(np.asarray(p, float), "clique-moments", 0.0))
    if partial:
        blocks = [(b.b, sol.moments.get(nm)) for nm, b in zip(names, u.gram.blocks)]
        p = _first_moments(blocks, n)
        if p is not None:
            cands.append(Candidate(p, "first-moments", 0.0))
        cands += [Candidate(q, "second-moments", 0.0) for q in second_moment_candidates(blocks, n)]
    return cands


def _violation_of(eq, ineq):
    """:func:`feasibility_violation` with the constraints compiled once (for many points)."""
    ce, ci = (_Compiled(eq) if eq else None), (_Compiled(ineq) if ineq else None)
    se = np.array([max(1.0, g.max_abs_coefficient()) for g in eq])
    si = np.array([max(1.0, h.max_abs_coefficient()) for h in ineq])

    def violation(p) -> float:
        worst = float(np.max(np.abs(ce.values(p)) / se)) if ce is not None else 0.0
        if ci is not None:
            worst = max(worst, float(np.max(np.maximum(0.0, -ci.values(p)) / si)))
        return worst
    return violation


def value_shift(f: Polynomial, eq, ineq, p: np.ndarray) -> float:
    """How far f may fall from p to the constraints, to first order: ||grad f(p)|| times the largest distance
    estimate (D_k r_k + e_k) / ||grad g_k(p)|| of a violated or active constraint (r_k = |g_k(p)| for an equality,
    max(0, -h_k(p)) for an inequality, D_k its degree, e_k the round-off of its evaluation at p; inf where its
    gradient vanishes or its Newton step toward the set does not halve r_k).  A candidate is feasible within
    :meth:`~sospoly.Tolerances.feasible` by the constraint's *value*: a squared constraint (x^2 + y^2 - 1)^2 = 0
    passes 1e-3 off its set, and f there lies ~1e-4 below the minimum (review 21a F3); :func:`sospoly.minimize`
    takes a point's value as an upper bound only where this shift is within the gap tolerance.  The degree covers a
    constraint vanishing to a higher order (r = |h|^m: r / ||grad r|| is 1/m of the distance, m <= D); the round-off
    term a point whose constraints vanish to round-off where their gradient is tiny (a cusp y^2 = x^3 in shifted
    variables met to 1e-15 at x = -5e-5, review 21c F2: the set's place is not resolved there)."""
    return value_shift_of(f, eq, ineq)(p)


#: the round-off of a polynomial's evaluation, relative to the sum of its terms' magnitudes (:func:`value_shift_of`)
EVAL_ROUNDOFF = 64 * np.finfo(float).eps


def value_shift_of(f: Polynomial, eq, ineq):
    """:func:`value_shift` as a function of the point, the polynomials compiled once (many candidates)."""
    fc = _Compiled([f])
    parts = [(_Compiled(polys), np.array([max(1, q.degree) for q in polys], float), viol)
             for polys, viol in ((eq, np.abs), (ineq, lambda v: np.maximum(0.0, -v))) if polys]

    def shift(p) -> float:
        p = np.asarray(p, float)
        worst = 0.0
        for c, deg, viol in parts:
            v = c.values(p)
            r, noise = viol(v), EVAL_ROUNDOFF * c.magnitudes(p)
            near = (r > 0) | (np.abs(v) <= noise)          # violated, or active to round-off
            if not np.any(near):
                continue
            J = c.jacobian(p)
            g = np.linalg.norm(J, axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                d = np.where(near, np.where(g > 0, (deg * r + noise) / g, np.inf), 0.0)
            d = np.where(_linear_model_fails(c, p, v, J, g, r > noise, noise), np.inf, d)
            worst = max(worst, float(np.max(d)))
        if worst == 0.0:
            return 0.0
        grad = float(np.linalg.norm(fc.jacobian(p)[0]))
        return grad * worst if np.isfinite(worst) else (0.0 if grad == 0.0 else np.inf)
    return shift


def _linear_model_fails(c: _Compiled, p: np.ndarray, v: np.ndarray, J: np.ndarray, g: np.ndarray,
                        which: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """Per constraint in ``which`` (violated beyond its evaluation's round-off at p, ``noise``): does its Newton step
    toward the set (p - v_k grad_k / |grad_k|^2) fail to halve the violation beyond the round-off?  Then the first-order
    distance means nothing (review 21c F2: on the cusp y^2 = x^3 at x < 0 the gradient points along y, whose step
    leaves g > 0: no feasible point is near)."""
    out = np.zeros(len(v), bool)
    for k in np.nonzero(which & (g > 0))[0]:
        q = p - v[k] * J[k] / (g[k] * g[k])
        tol = max(float(noise[k]), EVAL_ROUNDOFF * float(c.magnitudes(q)[k]))
        out[k] = abs(float(c.values(q)[k])) > 0.5 * abs(float(v[k])) + tol
    return out


def feasible_points(f, eq, ineq, cands, tol: Tolerances, refine: bool, deadline=None):
    """(f(p), p) of the feasible candidates, lowest first, near-duplicates merged; each polished first (``refine``)
    while the ``deadline`` (None: none) has not passed."""
    pts, raw = [], []
    violation = _violation_of(eq, ineq)
    for cand in cands:
        p = np.asarray(cand.point, float)
        if not np.all(np.isfinite(p)):
            continue
        # the same point extracted twice (Gram kernel and moments, clique and dense blocks) is polished once
        R = np.array(raw) if raw else None
        if R is not None and np.any(_norms(p - R) <= 1e-8 * np.maximum(1.0, _norms(R))):
            continue
        raw.append(p)
        if refine and not (deadline is not None and deadline.expired):
            q = _polish(f, eq, ineq, p)
            if q is not None and tol.feasible(violation(q)):
                # the polished point replaces the raw one: a raw candidate that violates a constraint
                # by less than the tolerance may still have f below the true minimum (no upper bound)
                pts.append(q)
                continue
        pts.append(p)
    found = [(float(f.evaluate(p)), p) for p in pts if tol.feasible(violation(p))]
    return dedupe_points(sorted(found, key=lambda t: t[0]))


def dedupe_points(found, rtol: float = 1e-4):
    """Merge candidates closer than rtol*max(1,|p|) (extraction noise), keeping the lowest f."""
    uniq, kept = [], []
    for val, p in found:
        K = np.array(kept) if kept else None
        if K is None or np.all(_norms(p - K) > rtol * np.maximum(1.0, _norms(K))):
            uniq.append((val, p))
            kept.append(p)
    return uniq


def _norms(A: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of A (n, k)."""
    return np.sqrt(np.einsum("ij,ij->i", A, A))
