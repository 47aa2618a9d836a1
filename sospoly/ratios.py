"""Sum-of-ratios objectives: certified lower bounds of  sum_i p_i(v) / q_i(v)  on K = {g = 0, h >= 0}.

Formulation (Bugarin, Henrion & Lasserre, "Minimizing the sum of many rational functions", Math. Prog.
Comp. 2016; TSSOS's ``SumOfRatios``).  With q_i > 0 on K, for polynomials w_i with sum_i w_i = lambda
(a constant) and p_i - w_i q_i >= 0 on K for every i,

    sum_i p_i(v) / q_i(v)  >=  sum_i w_i(v)  =  lambda      for every v in K,

so maximising lambda over such w_i gives a lower bound.  Nonnegativity on K is certified by Putinar
certificates (an SOS polynomial and SOS / free multipliers of the constraints, each of degree
``degree``): w_2, ..., w_m are free polynomials of degree ``degree - max deg q_i`` and
w_1 = lambda - w_2 - ... - w_m.  Dually the i-th certificate's moment matrix is that of q_i^{-1} mu
for one probability measure mu on K (the measures of the BHL moment formulation), so its atoms are
minimisers.

**Positive denominators.** The bound is only valid where every q_i > 0 on K, so each q_i is
certified first: ``sospoly.minimize(q_i, eq, ineq)`` must return a lower bound > 0 (kept in
``RatioResult.denominator_bounds``); otherwise the status is ``INFEASIBLE`` with a message naming
the denominator and no bound is reported.

**A proven bound.** The solver's lambda is reported only as far as it is proven
(:func:`sospoly.ratios_proof.proven_ratio_bound`): the certificates' identity residuals, recomputed in exact
arithmetic, and PSD defects are bounded on the box the constraints imply and subtracted; a set the constraints do
not bound gives status ``UNPROVEN`` and no bound.

The upper bound is the objective at feasible candidates (moment atoms and their local polish by SLSQP
on the rational objective); ``optimal`` follows :meth:`sospoly.Tolerances.certified` at the scale of
the objective's value.
"""
from __future__ import annotations

import logging
import math
import numbers
import time
from dataclasses import dataclass

import numpy as np

from .algebra.polynomial import Polynomial, checked_gens
from .algebra.basis import sigma
from .analysis.extraction import extract_from_moment
from .analysis.proof import constraint_box
from .budget import as_budget
from .certificates.program import SOSProgram
from .certificates.psatz import common_gens
from .lowering.conic import GramForm
from .ratios_proof import proven_ratio_bound
from .scaling import balancing, lifted, pow2_above, used_gens
from .solvers.solve import solve_program
from .status import SolveStatus
from .tolerances import Tolerances, as_tolerances

__all__ = ["RatioResult", "minimize_ratios"]

#: (Gram form, back-end) tried in turn while a solve ends numerically (as :func:`sospoly.minimize` does)
_RETRIES = ((GramForm.IMAGE, "clarabel"), (GramForm.KERNEL, "clarabel"), (GramForm.IMAGE, "cvxpy"))
_NUMERICAL = (SolveStatus.NUMERICAL_ERROR, SolveStatus.INACCURATE, SolveStatus.CHECK_FAILED)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RatioResult:
    """Outcome of :func:`minimize_ratios`: bounds of min sum p_i/q_i on K, minimisers, the certified lower
    bounds of every q_i on K, the program's size and the solution (Gram and moment matrices)."""
    status: SolveStatus
    lower_bound: float | None
    upper_bound: float | None
    minimizers: tuple
    optimal: bool
    n_lmivar: int
    degree: int
    denominator_bounds: tuple
    gens: tuple
    solution: object = None
    seconds: float = 0.0
    message: str = ""


def _constraint_list(seq, what: str) -> list:
    """``eq`` / ``ineq`` as a list of Polynomials or real numbers (TypeError naming the entry otherwise)."""
    if isinstance(seq, (str, bytes, Polynomial)) or not hasattr(seq, "__iter__"):
        raise TypeError(f"minimize_ratios {what} must be a sequence of polynomials, got {type(seq).__name__}")
    out = list(seq)
    for k, v in enumerate(out):
        if not isinstance(v, (Polynomial, int, float)) or isinstance(v, bool):
            raise TypeError(f"minimize_ratios {what}[{k}] must be a Polynomial or a number, got {type(v).__name__}")
    return out


def _check_terms(terms, eq, ineq, gens):
    terms = list(terms)
    if not terms:
        raise ValueError("minimize_ratios terms must hold at least one (p, q) pair")
    for k, t in enumerate(terms):
        if not (isinstance(t, (tuple, list)) and len(t) == 2):
            raise TypeError(f"minimize_ratios terms[{k}] must be a (p, q) pair of polynomials")
        for what, v in zip("pq", t):
            if not isinstance(v, (Polynomial, int, float)) or isinstance(v, bool):
                raise TypeError(f"minimize_ratios terms[{k}].{what} must be a Polynomial or a number, "
                                f"got {type(v).__name__}")
    eq, ineq = _constraint_list(eq, "eq"), _constraint_list(ineq, "ineq")
    polys = [Polynomial.constant(float(v)) if not isinstance(v, Polynomial) else v
             for t in terms for v in t] + list(eq) + list(ineq)
    gens = checked_gens(gens) if gens is not None else common_gens(*polys)
    if not gens:
        raise ValueError("minimize_ratios: the problem has no variables")
    conv = [p.with_gens(gens) if isinstance(p, Polynomial) else Polynomial.constant(float(p), gens) for p in polys]
    m = len(terms)
    pairs = [(conv[2 * k], conv[2 * k + 1]) for k in range(m)]
    for k, (_, q) in enumerate(pairs):
        if q.is_zero:
            raise ValueError(f"minimize_ratios terms[{k}].q is the zero polynomial")
    return pairs, tuple(conv[2 * m:2 * m + len(eq)]), tuple(conv[2 * m + len(eq):]), gens


def _normalised(pairs, eq, ineq):
    """Each (p_i, q_i) divided by the power of two at or above max|coef q_i| (the ratio unchanged), then every p_i
    by the power of two F at or above the largest remaining coefficient of the p_i (the objective / F), every
    constraint by its own such power: exact in floating point, so the normalised program *is* the caller's
    (its proven bound times F is one of the caller's problem)."""
    pairs = [(p * (1.0 / _pow2(q)), q * (1.0 / _pow2(q))) for p, q in pairs]
    F = _pow2_of(max(p.max_abs_coefficient() for p, _ in pairs))
    pairs = [(p * (1.0 / F), q) for p, q in pairs]
    return (pairs, tuple(g * (1.0 / _pow2(g)) for g in eq), tuple(h * (1.0 / _pow2(h)) for h in ineq), F)


def _pow2(p) -> float:
    return _pow2_of(p.max_abs_coefficient())


def _pow2_of(m: float) -> float:
    """The power of two at or just above m (1 for 0 or a non-finite m; :func:`sospoly.scaling.pow2_above`)."""
    return pow2_above(m)


def _degree(pairs, eq, ineq, degree):
    need = max([max(p.degree, q.degree, 0) for p, q in pairs] + [g.degree for g in eq] + [h.degree for h in ineq])
    need += need % 2
    if degree is None:
        return max(need, 2)
    if isinstance(degree, (bool, np.bool_)) or not isinstance(degree, numbers.Real):
        raise TypeError(f"minimize_ratios degree must be an even integer, got {type(degree).__name__} {degree!r}")
    if not math.isfinite(degree) or int(degree) != degree or degree % 2 or degree < need:
        raise ValueError(f"minimize_ratios degree must be an even integer >= {need}, got {degree!r}")
    return int(degree)


def _weights(pairs) -> list:
    """a_k = 1 / (the power of two at or above max|coef p_k|): certificate k is a_k (p_k - w_k q_k) - ... SOS, the
    same constraint (a positive factor, exact), its Gram matrix at the scale of its own ratio.  Without it a ratio
    1e6 times smaller than another had a Gram block ~1e-6 whose round-off failed the solver's PSD check relative to
    that block on every back-end (review 43b M3: a numerator x1e6 gave no bound at all)."""
    return [1.0 / _pow2(p) for p, _ in pairs]


def _build(pairs, eq, ineq, gens, degree):
    """The program of the module docstring: maximise lambda (block 'lambda'); (program, SOS constraint names, the
    weights a_k of :func:`_weights`)."""
    prog = SOSProgram(gens)
    lam = prog.scalar("lambda")
    dw = degree - max(q.degree for _, q in pairs)
    ws = [prog.free_poly(dw, name=f"w{k}") for k in range(1, len(pairs))]
    w0 = lam - sum(ws[1:], ws[0]) if ws else lam * 1.0
    names, weights = [], _weights(pairs)
    for k, (p, q) in enumerate(pairs):
        w = w0 if k == 0 else ws[k - 1]
        expr = (p - w * q) * weights[k]
        for j, g in enumerate(eq):
            expr = expr - prog.free_poly(degree - g.degree, name=f"r{k}_{j}") * g
        for j, h in enumerate(ineq):
            expr = expr - prog.sos_poly(degree - h.degree, name=f"s{k}_{j}") * h
        names.append(prog.add_sos(expr, degree=degree, name=f"u{k}").name)
    prog.maximize(lam)
    return prog, names, weights


def _objective(pairs):
    def value(v):
        return float(sum(p(v) / q(v) for p, q in pairs))
    return value


def _candidates(prog, names, sol, tol, n):
    pts = []
    for name in names:
        M = sol.moments.get(name)
        if M is None:
            continue
        basis = prog.sos_constraints[[c.name for c in prog.sos_constraints].index(name)].gram.blocks[0].b
        try:
            pts += [c.point for c in extract_from_moment(M, basis, tol) if c.point.shape == (n,)]
        except ValueError:
            continue
    return pts


def _polish(obj, eq, ineq, x0):
    from scipy.optimize import minimize as sp_min

    from .analysis.candidates import slsqp_equalities

    eq = slsqp_equalities(list(eq), np.asarray(x0, float))         # (at most n: SLSQP's heap, review 38a M5)
    cons = [{"type": "eq", "fun": (lambda v, g=g: g(v))} for g in eq] + \
        [{"type": "ineq", "fun": (lambda v, h=h: h(v))} for h in ineq]
    try:
        res = sp_min(obj, x0, method="SLSQP", constraints=cons, options={"ftol": 1e-14, "maxiter": 300})
    except (ValueError, ZeroDivisionError, FloatingPointError):
        return None
    return np.asarray(res.x, float) if np.all(np.isfinite(res.x)) else None


def _found(prog, names, sol, tol, n: int, pairs, eq, ineq) -> list:
    """(value, point) of the feasible candidates (moment atoms and their polish), ascending and distinct; starts
    outside twice the box the constraints imply are skipped (atoms at ~1e16 cost SLSQP ~0.8 s each, review 44c M3)."""
    obj = _objective(pairs)
    found = []
    box = constraint_box(eq, ineq, n, partial=True)
    for p in _candidates(prog, names, sol, tol, n):
        if not np.all(np.abs(p) <= 2.0 * box + 1.0):
            continue
        for v in (p, _polish(obj, eq, ineq, p)):
            if v is not None and _feasible(v, eq, ineq, pairs, tol):
                found.append((obj(v), v))
    return _distinct(sorted(found, key=lambda t: t[0]))


def _feasible(v, eq, ineq, pairs, tol) -> bool:
    viol = max([abs(g(v)) / max(1.0, g.max_abs_coefficient()) for g in eq] +
               [max(0.0, -h(v)) / max(1.0, h.max_abs_coefficient()) for h in ineq] + [0.0])
    return bool(tol.feasible(viol)) and all(q(v) > 0 for _, q in pairs)


def _distinct(found, rtol: float = 1e-4):
    out = []
    for val, v in found:
        if all(np.linalg.norm(v - w) > rtol * max(1.0, np.linalg.norm(w)) for _, w in out):
            out.append((val, v))
    return out


def _denominator_bounds(pairs, eq, ineq, gens, tol, backend, budget):
    """Certified lower bounds of every q_i on K (sospoly.minimize), the index of one not certified > 0 (or None),
    and the empty-set result of minimize when bounding a q_i proved K empty (its lower bound +inf; else None)."""
    from .minimize import minimize

    out = []
    for k, (_, q) in enumerate(pairs):
        if q.degree <= 0:
            out.append(float(q.coefficient((0,) * len(gens))))
        else:
            r = minimize(q, eq, ineq, gens=gens, tolerances=tol, backend=backend, budget=budget)
            if r.lower_bound == np.inf:                 # K proven empty (review 38a L6): no q_i matters
                return tuple(out) + (np.inf,), None, r
            ok = r.status == SolveStatus.OPTIMAL and r.lower_bound is not None
            out.append(r.lower_bound if ok else -np.inf)
        if not out[-1] > 0:
            return tuple(out), k, None
    return tuple(out), None, None


def minimize_ratios(terms, eq=(), ineq=(), degree: int | None = None, *, gens=None, backend=None,
                    tolerances: Tolerances | None = None, budget=None) -> RatioResult:
    """Certified lower bound (and minimisers) of sum_i p_i / q_i on {eq = 0, ineq >= 0} (module docstring).

    ``terms``: (p_i, q_i) pairs of Polynomials (numbers allowed); every q_i must be certified > 0 on the set.
    The data are scaled exactly (the variables by powers of two that balance the coefficients,
    :func:`sospoly.scaling.balancing`; each ratio's q_i, the objective and each constraint divided by a power of
    two near its largest coefficient), so the program solved is the caller's; the lower bound is the one proven
    from the solved certificate (:mod:`sospoly.ratios_proof`: its identity residual in exact arithmetic and its
    PSD defects on the box the constraints imply; none there: status ``UNPROVEN``, no bound), and bounds and
    minimisers are reported in the caller's units.  ``budget`` (:class:`sospoly.Budget`): a Gram side
    above ``max_gram_side`` is refused (status ``BUDGET_EXCEEDED``) and the solve stops at ``time_limit``.
    """
    t0 = time.perf_counter()
    tol, budget = as_tolerances(tolerances), as_budget(budget)
    pairs0, eq0, ineq0, gens = _check_terms(terms, eq, ineq, gens)
    used = used_gens(gens, *[v for pq in pairs0 for v in pq], *eq0, *ineq0)
    if 0 < len(used) < len(gens):               # a variable in no polynomial: solved without it (no box holds it)
        res = minimize_ratios([(p.with_gens(used), q.with_gens(used)) for p, q in pairs0],
                              [g.with_gens(used) for g in eq0], [h.with_gens(used) for h in ineq0], degree,
                              gens=used, backend=backend, tolerances=tolerances, budget=budget)
        return lifted(res, gens, used)
    degree = _degree(pairs0, eq0, ineq0, degree)
    scaling = balancing([v for pq in pairs0 for v in pq] + list(eq0) + list(ineq0), len(gens))
    pairs, eq, ineq, F = _normalised([(scaling.polynomial(p), scaling.polynomial(q)) for p, q in pairs0],
                                     [scaling.polynomial(g) for g in eq0], [scaling.polynomial(h) for h in ineq0])
    side = sigma(len(gens), degree // 2)
    if side > budget.max_gram_side:
        return RatioResult(SolveStatus.BUDGET_EXCEEDED, None, None, (), False, 0, degree, (), gens, None,
                           time.perf_counter() - t0, f"Gram side {side} exceeds max_gram_side {budget.max_gram_side}")
    dbounds, bad, empty = _denominator_bounds(pairs0, eq0, ineq0, gens, tol, backend, budget)
    if empty is not None:
        return RatioResult(empty.status, np.inf, None, (), False, 0, degree, dbounds, gens, None,
                           time.perf_counter() - t0, f"{empty.message} (proven while bounding the denominator "
                           f"terms[{len(dbounds) - 1}].q): every sum of ratios is bounded below by +inf there")
    if bad is not None:
        return RatioResult(SolveStatus.INFEASIBLE, None, None, (), False, 0, degree, dbounds, gens, None,
                           time.perf_counter() - t0, f"denominator terms[{bad}].q is not certified positive on the "
                           f"set (certified lower bound {dbounds[bad]}): the sum-of-ratios bound needs q_i > 0")
    prog, names, weights = _build(pairs, eq, ineq, gens, degree)
    deadline = budget.deadline()
    for form, be in _RETRIES if backend is None else ((GramForm.IMAGE, backend),):
        sol = solve_program(prog, be, form, tolerances=tol, deadline=deadline)
        if sol.status not in _NUMERICAL or deadline.expired:
            break
    if sol.status != SolveStatus.OPTIMAL:
        return RatioResult(sol.status, None, None, (), False, prog.n_lmivar(), degree, dbounds, gens, sol,
                           time.perf_counter() - t0, sol.message)
    relaxed = float(sol.objective)
    q_unit = [_pow2(scaling.polynomial(q)) for _, q in pairs0]          # the divisors of the normalised q_i
    lower, note = proven_ratio_bound(prog, names, sol, pairs, eq, ineq, [b / u for b, u in zip(dbounds, q_unit)],
                                     weights)
    found = _found(prog, names, sol, tol, len(gens), pairs, eq, ineq)
    upper = found[0][0] if found else None
    status, optimal, msg = SolveStatus.OPTIMAL, False, note
    if not np.isfinite(lower):
        status, lower = SolveStatus.UNPROVEN, None
        msg = f"the relaxation's value {relaxed * F:.10g} is not proven a lower bound ({note})"
    elif upper is not None:
        scale = max(1.0, abs(upper))
        if tol.contradicts(lower, upper, scale):
            status, msg = SolveStatus.INCONSISTENT, f"lower bound {lower * F:.10g} exceeds the objective " \
                                                     f"{upper * F:.10g} at a point that meets the constraints only " \
                                                     "within the tolerances: not reported as an upper bound"
            upper, found = None, []     # (the proven bound stays: a result never contradicts itself, review 38a M4)
        else:
            optimal = bool(tol.certified(lower, upper, scale))
            lower = tol.consistent(lower, upper)
    mins = tuple(scaling.to_original(v) for val, v in found
                 if upper is not None and val <= upper + tol.gap_tolerance(upper))
    return RatioResult(status, None if lower is None else lower * F, None if upper is None else upper * F, mins,
                       optimal, prog.n_lmivar(),
                       degree, dbounds, gens, sol, time.perf_counter() - t0, msg)
