"""Re-centring a polynomial program at a candidate minimiser (strategy step 6 of :func:`sospoly.minimize`).

The certificate rule (:mod:`sospoly.tolerances`) measures a gap at the problem's own scale, the largest
coefficient of the balanced objective.  Expanded at the origin, a translated problem such as

    f(v) = (v - 1000)^4 - 3 (v - 1000)^2 + 1          (minimum -1.25 at v = 1000 +- sqrt(1.5))

has coefficients up to 1e12 while its values near the minimiser are O(1): the scale at the origin is the
size of a cancellation, not of the problem, and a gap of 1e-6 of it (1e6 here) says nothing about the
minimum.  The problem's scale *at the minimiser* is that of f(y + t) for t near the minimiser:

    scale_t(f) = the power of two above the largest coefficient of the balanced f(y + t)
                 (:func:`sospoly.scaling.scaled_program`, the same step 1 of ``minimize``).

``minimize`` decides at min(scale_0, scale_t) (:func:`cancellation_scale`; scale_t in the units that balance
f(y + t)'s terms of degree >= 2, which a minimum value 0 cannot unsettle), values f exactly at the points
(:func:`with_exact_values`: a floating-point value errs by eps times the cancelled terms), and when scale_t is
below scale_0 by ``CANCELLATION_BITS`` or more it solves the translated program as well (decided at its own
scale) and keeps the better of the two results (certified first, then the larger proven lower bound)
(:func:`translated_program`, :func:`result_in_original`):

* **exact.** t has at most ``T_BITS`` significant bits and the coefficients of p(y + t) are computed in
  rational arithmetic (every float is a dyadic rational, ``fractions.Fraction``); the translation is used
  only when every coefficient of every polynomial is exactly a float, so the translated program *is* the
  caller's program and its certificate is one of the caller's problem (integer and short-mantissa data,
  the case of the textbook problems, translate exactly; other data keep the first solve, decided at the
  scale above: a gap that is large at the minimiser's scale is then not a certificate);
* **inverse.** points map back by v = y + t (then f is evaluated at the mapped point in the caller's
  form), a ball ||v|| <= R holding a minimiser becomes ||y|| <= R + ||t||, and the moment matrices map by
  the basis change v^a = sum_{c <= a} binom(a, c) t^(a - c) y^c (a basis closed under divisors; a block
  whose basis is not is dropped).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from fractions import Fraction
from itertools import product

import numpy as np

from .algebra.polynomial import Polynomial
from .analysis.candidates import feasibility_violation
from .scaling import MAX_EXPONENT, pow2_above, scaled_program

__all__ = ["Cancellation", "CANCELLATION_BITS", "T_BITS", "MAX_TERMS", "SCALE_MAX_TERMS", "RECENTRE_ROUNDS",
           "translation_point", "translated", "cancellation_scale", "scale_of_result", "translated_program",
           "result_in_original", "exact_value", "exact_fraction", "with_exact_values", "pooled", "recentred",
           "in_callers_units"]

#: significant bits kept of each coordinate of the translation t.
T_BITS = 12
#: solve the translated program too when the scale at the minimiser is this many bits below the origin's.
CANCELLATION_BITS = 8
#: a coordinate of the translation shorter than this in the balanced variables is 0 (the minimiser is at the origin
#: in it: 1e-27 there would add terms of 1e-27 that skew the balancing of the measure).
NEGLIGIBLE_SHIFT = 2.0 ** -20
#: a translated coefficient below this fraction of the magnitudes that cancel in it is round-off (64 ulps).
CANCELLED = 64 * float(np.finfo(float).eps)
#: candidates re-valued exactly per result.
MAX_CANDIDATES = 20
#: translated programs solved at most per call (each at a best point whose scale is ``CANCELLATION_BITS`` below the
#: last translation's; review 39b: Rosenbrock shifted by 1024, whose first solve stops 8458 above the minimum 0 at a
#: point of scale 1.1e12, certifies at (1025, 1) from the second translation).
RECENTRE_ROUNDS = 3
#: a translation that would expand to more terms than this is not attempted (its cost would dominate).
MAX_TERMS = 5000
#: the scale at a minimiser (:func:`cancellation_scale`) is measured up to this many expanded terms (~0.2-2 s);
#: beyond, a minimiser away from the origin gets no certificate (:func:`with_exact_values`): the origin's scale may
#: be 1e13 times the minimiser's (review 25b F3).
SCALE_MAX_TERMS = 20000


def translation_point(x) -> np.ndarray:
    """x rounded to ``T_BITS`` significant bits per coordinate (0 stays 0)."""
    x = np.asarray(x, float)
    m, e = np.frexp(x)
    return np.ldexp(np.round(np.ldexp(m, T_BITS)), e - T_BITS)


def _expanded_terms(p: Polynomial) -> int:
    return sum(math.prod(int(a) + 1 for a in e) for e in p.terms)


def _translated_sums(p: Polynomial, t) -> tuple[dict, dict]:
    """(exact coefficients of p(y + t), the sums of the absolute values of their contributions), by exponent."""
    t = [Fraction(float(ti)) for ti in np.asarray(t, float)]
    acc: dict = {}
    mag: dict = {}
    for a, c in p.terms.items():
        cf = Fraction(float(c))
        live = [i for i, ai in enumerate(a) if ai]        # (a variable absent from the term contributes b = 0 only)
        per_var = [[(b, math.comb(a[i], b) * t[i] ** (a[i] - b)) for b in range(a[i] + 1)] for i in live]
        for combo in product(*per_var):
            w = cf
            for _, coef in combo:
                w *= coef
            if w:
                key = [0] * len(a)
                for i, (b, _) in zip(live, combo):
                    key[i] = b
                key = tuple(key)
                acc[key] = acc.get(key, 0) + w
                mag[key] = mag.get(key, 0) + abs(w)
    return acc, mag


def translated(p: Polynomial, t, exact: bool = True) -> Polynomial | None:
    """p(y + t) over p's generators: computed in rational arithmetic, then each coefficient as a float.
    ``exact``: None unless every coefficient is exactly a float (else rounded to nearest)."""
    acc, _ = _translated_sums(p, t)
    terms = {}
    for key, w in acc.items():
        if w == 0:
            continue
        fw = float(w)
        if exact and Fraction(fw) != w:
            return None
        terms[key] = fw
    return Polynomial(p.gens, terms)


def _significant_part(p: Polynomial, t) -> Polynomial:
    """p(y + t) without the coefficients that are round-off of a cancellation (below ``CANCELLED`` times the sum
    of the magnitudes they cancel from): the data's own rounding, not structure, so not a scale."""
    acc, mag = _translated_sums(p, t)
    return Polynomial(p.gens, {k: float(w) for k, w in acc.items() if w and abs(w) > CANCELLED * mag[k]})


def exact_fraction(p: Polynomial, x) -> Fraction:
    """p(x) in rational arithmetic at the float point x, exactly."""
    xs = [Fraction(float(v)) for v in np.asarray(x, float)]
    total = Fraction(0)
    for a, c in p.terms.items():
        term = Fraction(float(c))
        for xi, ai in zip(xs, a):
            if ai:
                term *= xi ** int(ai)
        total += term
    return total


def exact_value(p: Polynomial, x) -> float:
    """p(x) evaluated in rational arithmetic (:func:`exact_fraction`) and rounded up to a float (a valid upper bound
    of p(x): where coefficients cancel, a floating-point evaluation at a point far from the origin errs by
    eps * sum_a |c_a| |x^a|, far above the gap being decided)."""
    total = exact_fraction(p, x)
    v = float(total)
    return float(np.nextafter(v, np.inf)) if Fraction(v) < total else v


def with_exact_values(res, f: Polynomial, tol, scale: float):
    """``res`` with its candidates re-valued exactly (:func:`exact_value`), the upper bound f at the best, and the
    decision of :mod:`sospoly.tolerances` made again at ``scale`` on those numbers."""
    pts = [np.asarray(p, float) for p in (res.candidates or res.minimizers)][:MAX_CANDIDATES]
    vals = sorted(((exact_value(f, p), p) for p in pts if np.all(np.isfinite(p))), key=lambda vp: vp[0])
    vals = [(v, p) for v, p in vals if np.isfinite(v)]
    upper = vals[0][0] if vals else None
    lower, optimal, status = res.lower_bound, res.optimal, res.status
    if lower is not None and upper is not None:
        if tol.contradicts(lower, upper, scale):
            optimal, status = False, type(status).INCONSISTENT
        else:
            optimal = optimal and bool(tol.certified(lower, upper, scale))
            lower = tol.consistent(lower, upper)
    else:
        optimal = False
    message = res.message
    if res.status == type(res.status).INCONSISTENT and status == res.status and lower is not None \
            and upper is not None and not tol.contradicts(lower, upper, scale):
        # the contradiction came from a float value of f (review 25b F5: Robinson's polynomial "-1.96e56" at a far
        # candidate, f >= 0 everywhere): the exact values no longer contradict the proven bound
        status = type(res.status).OPTIMAL
        message = "; ".join(m for m in message.split("; ") if "numerical failure" not in m)
        # ... and the decision is the certificate rule on them (review 43b M1: status OPTIMAL, a gap of 3e-9 against
        # a tolerance of 8e-6, optimal False), where the solve itself ended optimal
        optimal = getattr(res.solution, "status", status) == status and bool(tol.certified(lower, upper, scale))
    if optimal and vals and _expanded_terms(f) > SCALE_MAX_TERMS and _away_from_origin(f, vals[0][1]):
        # the scale at the minimiser needs f(y + t) expanded: not computed, and the origin's may be 1e8 times too
        # large (a translated quartic in 10 variables: "optimal" with a gap of 5644 at scale 3.5e13, review 25b F3)
        optimal = False
        note = f"not certified: f(y + t) at the minimiser has more than {SCALE_MAX_TERMS} terms, so the gap cannot " \
               "be decided at the minimiser's scale"
        message = "; ".join(m for m in (message, note) if m)
    solved = getattr(res.solution, "status", status)
    if status == type(status).OPTIMAL and not optimal and solved != status:
        status = solved                 # a certificate withdrawn here: the solve's own status (review 38a M2)
    near = tol.gap_tolerance(upper, scale) if upper is not None else 0.0
    mins = tuple(p for v, p in vals if v <= upper + near) if upper is not None else ()
    if status == type(status).INCONSISTENT and upper is not None:
        # the proven lower bound exceeds f exactly valued at points that meet the constraints only within the
        # feasibility tolerance: they are no upper bound (the constraints may have no real solution at all; review
        # 38a M4: two concentric circles 1e-6 apart); the lower bound stays, so the result never contradicts itself
        message = "; ".join(m for m in (message, f"f = {upper:.10g} at the best candidate, which meets the "
                                        "constraints only within the tolerances: not reported as an upper bound") if m)
        upper, mins = None, ()
    return replace(res, lower_bound=lower, upper_bound=upper, minimizers=mins, candidates=tuple(p for _, p in vals),
                   optimal=optimal, status=status, scale=scale, message=message)


def in_callers_units(res, f: Polynomial, eq, ineq, tol):
    """``res`` with the candidates that meet the constraints *as given* within ``tol.feasibility`` (the rule of
    :mod:`sospoly.tolerances`, :func:`sospoly.analysis.candidates.feasibility_violation`) and decided again on them
    (:func:`with_exact_values` at ``res.scale``).  The candidates are screened on the balanced, normalised program,
    whose coefficients the rule reads in other units: a minimiser 2.2e-6 (3.6e-5 without the polish) outside a
    constraint by the caller's measure was reported as a certified minimiser (review 42b F2)."""
    pts = [np.asarray(p, float) for p in (res.candidates or res.minimizers)]
    if not pts or (not eq and not ineq):
        return res
    keep = tuple(p for p in pts if feasibility_violation(p, eq, ineq) <= tol.feasibility)
    if len(keep) == len(pts):
        return res
    note = f"{len(pts) - len(keep)} candidate(s) outside the constraints as given (feasibility tolerance " \
           f"{tol.feasibility:g}) not reported"
    out = with_exact_values(replace(res, candidates=keep, minimizers=keep[:1]), f, tol, res.scale)
    return replace(out, message="; ".join(m for m in (out.message, note) if m))


def _away_from_origin(f: Polynomial, x) -> bool:
    """Is the translation point of x (:func:`translation_point`) away from the origin, in the balanced units of
    :func:`cancellation_scale`?"""
    p0 = scaled_program(f, (), (), "fixed", None)
    t = translation_point(x)
    return bool(np.any(np.abs(p0.scaling.to_scaled(t)) >= NEGLIGIBLE_SHIFT))


@dataclass(frozen=True)
class Cancellation:
    """The measure of :func:`cancellation_scale`: ``s0`` the scale at the origin, ``st`` the scale at the
    translation point ``t`` (<= s0)."""
    s0: float
    st: float
    t: np.ndarray

    @property
    def worth_translating(self) -> bool:
        return worth_translating(self.s0, self.st)

    @property
    def decision_scale(self) -> float:
        """The problem's own scale for the decision: the smaller of the two."""
        return self.st


def _structure_scale(ft: Polynomial) -> float | None:
    """The power of two above the largest coefficient of ft in the variable units that balance its terms of
    degree >= 2 (least squares on a . k - mu ~ -log2 |c_a|, k rounded).  The terms of degree 0 and 1 (where t is
    and the slope there) take no part in the fit: at a minimiser they vanish or nearly, and would let the units
    drift (a minimum value 0 leaves nothing to hold them); they count in the maximum."""
    high = [(a, c) for a, c in ft.terms.items() if sum(a) >= 2 and c]
    if not high:
        return None
    E = np.array([a for a, _ in high], float)
    A = np.hstack([E, -np.ones((len(E), 1))])
    b = -np.log2(np.abs(np.array([c for _, c in high], float)))
    k = np.clip(np.round(np.linalg.lstsq(A, b, rcond=None)[0][:-1]), -MAX_EXPONENT, MAX_EXPONENT)
    with np.errstate(over="ignore", under="ignore"):
        mags = [abs(float(c)) * 2.0 ** float(np.dot(a, k)) for a, c in ft.terms.items()]
    top = max(mags)
    if not (np.isfinite(top) and top > 0):
        return None
    return pow2_above(top)


def cancellation_scale(f: Polynomial, x) -> Cancellation:
    """The scale at the origin (the ``fscale`` of :func:`sospoly.scaling.scaled_program`) and at the translation
    point t of x (:func:`_structure_scale` of the significant part of f(y + t)): a measure, not a certificate."""
    p0 = scaled_program(f, (), (), "fixed", None)
    t = translation_point(x)
    t = np.where(np.abs(p0.scaling.to_scaled(t)) < NEGLIGIBLE_SHIFT, 0.0, t)      # coordinates already at the origin
    s0 = p0.fscale
    if not np.any(t) or _expanded_terms(f) > SCALE_MAX_TERMS:
        return Cancellation(s0, s0, t)
    st = _structure_scale(_significant_part(f, t))
    return Cancellation(s0, s0 if st is None else min(s0, st), t)


def scale_of_result(res, f: Polynomial, cut: Cancellation) -> float:
    """The decision scale of a result of step 8: the smallest of its program's scale and the scales at the first
    minimiser (``cut``) and at its own best point."""
    own = cancellation_scale(f, res.minimizers[0]).st if res.minimizers else np.inf
    return float(min(cut.decision_scale, res.scale, own))


def worth_translating(s0: float, st: float) -> bool:
    """The translation narrows the scale by at least ``CANCELLATION_BITS`` (then the translated program is solved
    too)."""
    return st > 0 and math.log2(s0 / st) >= CANCELLATION_BITS


def translated_program(t, f, eq, ineq, multiplier, radius):
    """(f_t, eq_t, ineq_t, multiplier_t, radius_t) of the module docstring, or None when a translation is not
    exact (or too large to expand)."""
    polys = [f, *eq, *ineq] + ([multiplier] if isinstance(multiplier, Polynomial) else [])
    if sum(_expanded_terms(p) for p in polys) > MAX_TERMS:
        return None
    out = [translated(p, t) for p in polys]
    if any(q is None for q in out):
        return None
    ft, rest = out[0], out[1:]
    eqt, ineqt = tuple(rest[:len(eq)]), tuple(rest[len(eq):len(eq) + len(ineq)])
    mult = rest[-1] if isinstance(multiplier, Polynomial) else multiplier
    rt = None
    if radius is not None:
        rt = float(np.nextafter(float(radius) + float(np.linalg.norm(t)) * (1 + 1e-15), np.inf))
    return ft, eqt, ineqt, mult, rt


def _moments_in_original(mm, t):
    """A moment matrix of y mapped to v = y + t (None when its basis is not closed under divisors)."""
    B = np.asarray(mm.basis, np.int64)
    index = {tuple(int(v) for v in row): i for i, row in enumerate(B)}
    T = np.zeros((len(B), len(B)))
    for i, a in enumerate(B):
        for c in product(*[range(int(ai) + 1) for ai in a]):
            j = index.get(tuple(c))
            if j is None:
                return None
            T[i, j] = math.prod(math.comb(int(ai), ci) * float(ti) ** (int(ai) - ci) for ai, ci, ti in zip(a, c, t))
    return replace(mm, matrix=T @ mm.matrix @ T.T)


def result_in_original(res, t):
    """The translated program's result in the caller's variables: points + t and the moment matrices mapped (the
    bounds are the same program's; :func:`with_exact_values` then values the points in the caller's form)."""
    t = np.asarray(t, float)
    mms = tuple(m for m in (_moments_in_original(mm, t) for mm in res.moment_matrices) if m is not None)
    return replace(res, minimizers=tuple(np.asarray(p, float) + t for p in res.minimizers),
                   candidates=tuple(np.asarray(p, float) + t for p in res.candidates), moment_matrices=mms)


def pooled(chosen, spare, f: Polynomial, tol, scale: float):
    """``chosen`` with the evidence of ``spare``, another solve of the same problem (an exact translation of it):
    the larger of their proven lower bounds and the points of both, valued exactly and decided again
    (:func:`with_exact_values`) at the smaller of ``scale`` and the scale at the best point -- a gap is measured at
    the problem's scale where its best known point is, not where a worse solve stopped."""
    return _pooled(chosen, spare, f, tol, scale)[0]


def _pooled(chosen, spare, f: Polynomial, tol, scale: float):
    """(:func:`pooled`, the :func:`cancellation_scale` at its best point or None: measured once, for
    :func:`recentred`'s next round too)."""
    lows = [r.lower_bound for r in (chosen, spare) if r.lower_bound is not None and not np.isnan(r.lower_bound)]
    half = MAX_CANDIDATES // 2
    pts = tuple(chosen.candidates or chosen.minimizers)[:half] + tuple(spare.candidates or spare.minimizers)[:half]
    merged = replace(chosen, lower_bound=max(lows) if lows else None, candidates=pts)
    out = with_exact_values(merged, f, tol, scale)
    if not out.minimizers:
        return out, None
    cut = cancellation_scale(f, out.minimizers[0])
    if cut.st < scale:
        out = with_exact_values(merged, f, tol, cut.st)
    return out, cut


def recentred(best, f: Polynomial, tol, solve_at, deadline, better):
    """Step 8 of :func:`sospoly.minimize` (module docstring): ``best`` decided at the scale of its minimiser, and
    while the scale at the best point found is ``CANCELLATION_BITS`` below the last translation's (at most
    ``RECENTRE_ROUNDS`` times, before the deadline), ``solve_at(t, res)`` -- the program translated exactly to t
    (solved to check ``res``), its result in the caller's variables, or None when the translation is not exact --
    pooled with it
    (:func:`pooled`; ``better(a, b)`` chooses whose solve the result reports)."""
    if not best.minimizers:
        return best
    # the minimiser by the exact values: float values of f cancel away from the origin (a candidate of a translated
    # Motzkin polynomial at +860 read as -9.8e4 was taken as the minimiser, and the origin's scale 1.8e19 decided a
    # 0.72 gap: review 42b F1)
    first = with_exact_values(best, f, tol, best.scale)          # an upper bound f(v^) never below f(v^)
    if not first.minimizers:
        return first
    cut = cancellation_scale(f, first.minimizers[0])
    if cut.st >= cut.s0:
        return first
    res = with_exact_values(best, f, tol, scale_of_result(first, f, cut))
    note, moved, last = f"scale {cut.s0:.3g} at the origin, {cut.st:.3g} at the minimiser", False, cut.s0
    for _ in range(RECENTRE_ROUNDS):
        if not worth_translating(last, cut.st) or deadline.expired:
            break
        other = solve_at(cut.t, res)
        if other is None:
            note += "; the translation to it is not exact in floating point (not solved there)"
            break
        other = replace(other, attempts=res.attempts + other.attempts)
        scale = min(res.scale, scale_of_result(other, f, cut))
        ahead = better(with_exact_values(other, f, tol, scale), res)
        res, there = _pooled(other, res, f, tol, scale) if ahead else _pooled(res, other, f, tol, scale)
        moved, last = moved or ahead, cut.st
        if there is None:
            break
        cut = there
        note += f"; {cut.st:.3g} at the next best point" if worth_translating(last, cut.st) else ""
    note = f"{'re-centred at the minimiser' if moved else 'decided at the minimiser scale'} ({note})"
    return replace(res, message="; ".join(m for m in (res.message, note) if m))
