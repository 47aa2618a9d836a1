"""Exact scaling of a polynomial program before it is solved (used by :func:`sospoly.minimize`).

Variables: v = D w with D = diag(2^k_1, ..., 2^k_n), k integers, so every coefficient c_a of a
polynomial becomes c_a 2^(a . k) -- a multiplication by a power of two, *exact* in floating point
(barring overflow and subnormals, which are refused).  The scaled program is therefore the same
program, bit for bit: a certificate proven for it is a certificate of the caller's program, and points
map back exactly (v = D w).  Objective and constraints are then divided by powers of two near their
largest coefficients (exact too).

The exponents k balance the coefficients: with one offset mu_j per polynomial, least squares on

    a . k - mu_j  ~  -log2 |c_a|      (every term a of every polynomial j),

rounded to integers.  f = M(s x, s y) (Motzkin) gives k = -log2 s (the Motzkin polynomial again); a
disc x^2 + y^2 <= 4 / s^2 becomes the disc of radius 2.  The scaling is used only when it narrows the
spread of the coefficients' magnitudes by at least ``MIN_GAIN_BITS`` (well-scaled programs stay as
given).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .algebra.polynomial import Polynomial

__all__ = ["VariableScaling", "ScaledProgram", "balancing", "uncapped", "power2_normalised", "scaled_program",
           "used_gens", "lifted", "pow2_above", "pow2_above_array", "MIN_GAIN_BITS", "MAX_EXPONENT", "MAX_POW2_EXP"]

#: the scaling is applied only when it narrows the largest log2-spread of the polynomials' coefficients by this.
MIN_GAIN_BITS = 4.0
#: |k_i| is capped here (2^200 ~ 1.6e60).
MAX_EXPONENT = 200
#: the largest binary exponent of a finite power of two: the power "at or just above" a magnitude in
#: [2^1023, the largest double] would be 2^1024, which overflows (a camera entry of 1e308 raised OverflowError, review
#: 29b F1), so :func:`pow2_above` stops at 2^1023 and a quotient by it is at most 2 in magnitude.
MAX_POW2_EXP = 1023


def pow2_above(m: float) -> float:
    """The power of two just above ``m`` > 0 (2^e with m = f 2^e, 1/2 <= f < 1; 2 for m = 1), at most
    2^MAX_POW2_EXP; 1 for 0 or a non-finite m.  Dividing by it is exact (barring underflow) and brings m into
    [1/2, 1), or [1, 2) at the cap."""
    if not (m > 0 and math.isfinite(m)):
        return 1.0
    return math.ldexp(1.0, min(math.frexp(m)[1], MAX_POW2_EXP))


def pow2_above_array(m: np.ndarray) -> np.ndarray:
    """The vectorised twin of :func:`pow2_above` (elementwise, the same numbers)."""
    m = np.asarray(m, float)
    ok = (m > 0) & np.isfinite(m)
    return np.where(ok, np.ldexp(1.0, np.minimum(np.frexp(np.where(ok, m, 1.0))[1], MAX_POW2_EXP)), 1.0)


@dataclass(frozen=True)
class VariableScaling:
    """v = 2^k w (elementwise): ``polynomial`` maps p(v) to p(2^k w) exactly; ``to_original`` /
    ``to_scaled`` map points."""
    k: np.ndarray
    #: the balancing wanted an exponent beyond ``MAX_EXPONENT`` (or would overflow): the scaled program is still the
    #: caller's, but its coefficients stay unbalanced, so the tolerances do not act at the problem's own scale
    capped: bool = False

    @classmethod
    def identity(cls, n: int, capped: bool = False) -> VariableScaling:
        return cls(np.zeros(n, np.int64), capped)

    @property
    def is_identity(self) -> bool:
        return not np.any(self.k)

    def polynomial(self, p: Polynomial) -> Polynomial:
        if self.is_identity or not p.terms:
            return p
        terms = {}
        for e, c in p.terms.items():
            terms[e] = math.ldexp(float(c), int(np.dot(e, self.k)))
        return Polynomial(p.gens, terms)

    def to_original(self, w) -> np.ndarray:
        return np.ldexp(np.asarray(w, float), self.k)

    def to_scaled(self, v) -> np.ndarray:
        return np.ldexp(np.asarray(v, float), -self.k)

    def radius(self, R: float) -> np.ndarray:
        """|w_i| <= R 2^-k_i: the box in w of the ball ||v|| <= R."""
        return np.ldexp(np.full(self.k.shape, float(R)), -self.k)


def _spread(polys) -> float:
    """The largest log2-spread max - min of |coefficients| over the polynomials."""
    out = 0.0
    for p in polys:
        c = np.abs(p.coefficients()) if p.terms else np.zeros(0)
        c = c[c > 0]
        if c.size:
            out = max(out, float(np.log2(c.max()) - np.log2(c.min())))
    return out


def balancing(polys, n: int) -> VariableScaling:
    """The variable scaling of the module docstring for polynomials over n common variables (identity when
    it gains less than ``MIN_GAIN_BITS`` or would overflow)."""
    polys = [p for p in polys if p.terms]
    rows, rhs = [], []
    for j, p in enumerate(polys):
        E, c = p.exponents(), np.abs(p.coefficients())
        for a, cj in zip(E, c):
            if cj > 0:
                row = np.zeros(n + len(polys))
                row[:n], row[n + j] = a, -1.0
                rows.append(row)
                rhs.append(-math.log2(cj))
    ident = VariableScaling.identity(n)
    if not rows:
        return ident
    A, b = np.array(rows), np.array(rhs)
    sol = np.linalg.lstsq(A, b, rcond=None)[0]
    wanted = np.round(sol[:n])
    capped = bool(np.any(np.abs(wanted) > MAX_EXPONENT))
    k = np.clip(wanted, -MAX_EXPONENT, MAX_EXPONENT).astype(np.int64)
    if not np.any(k):
        return ident
    sc = VariableScaling(k, capped)
    try:
        scaled = [sc.polynomial(p) for p in polys]
    except (OverflowError, ValueError):
        return VariableScaling.identity(n, True)
    for p, q in zip(polys, scaled):
        cq = np.abs(q.coefficients())
        if not np.all(np.isfinite(cq)) or np.any(cq < np.finfo(float).tiny) or len(q.terms) != len(p.terms):
            return VariableScaling.identity(n, True)
    return sc if _spread(polys) - _spread(scaled) >= MIN_GAIN_BITS else VariableScaling.identity(n, capped)


def power2_normalised(p: Polynomial) -> tuple[Polynomial, float]:
    """(p / 2^e, 2^e) with 2^e the power of two nearest above p's largest coefficient (exact division)."""
    m = p.max_abs_coefficient()
    if not m or not np.isfinite(m):
        return p, 1.0
    e = min(math.frexp(m)[1], MAX_POW2_EXP)
    return Polynomial(p.gens, {a: math.ldexp(float(c), -e) for a, c in p.terms.items()}), math.ldexp(1.0, e)


def _normalised(f, eq, ineq):
    """f and every constraint divided by a power of two near its largest coefficient (exact; same feasible
    set), and f's divisor."""
    fn, fs = power2_normalised(f)
    return fn, tuple(power2_normalised(g)[0] for g in eq), tuple(power2_normalised(h)[0] for h in ineq), fs


@dataclass(frozen=True)
class ScaledProgram:
    """The program as :func:`sospoly.minimize` solves it: balanced and normalised data, the variable scaling, the
    multiplier in the scaled variables, and a box |w_i| <= box_i holding a minimiser (None: unknown)."""
    fn: Polynomial
    eqn: tuple
    ineqn: tuple
    fscale: float
    scaling: VariableScaling
    multiplier: object
    box: np.ndarray | None
    ball: float | None = None           # ||w|| <= ball for the minimiser ``radius`` speaks of

def scaled_program(f, eq, ineq, multiplier, radius) -> ScaledProgram:
    """Step 1 of :func:`sospoly.minimize`, and the box of its step 2 (``radius``'s ball and the constraints'
    box, intersected)."""
    from .analysis.proof import constraint_box

    n = f.nvars
    sc = balancing([f, *eq, *ineq], n)
    fb, eqb, ineqb = sc.polynomial(f), tuple(sc.polynomial(g) for g in eq), tuple(sc.polynomial(h) for h in ineq)
    fn, eqn, ineqn, fs = _normalised(fb, eqb, ineqb)
    mult = sc.polynomial(multiplier.with_gens(f.gens)) if isinstance(multiplier, Polynomial) else multiplier
    box, ball = constraint_box(eqn, ineqn, n), None
    if radius is not None:
        r = sc.radius(radius)
        box, ball = (r if box is None else np.minimum(box, r)), float(np.max(r))
    return ScaledProgram(fn, eqn, ineqn, fs, sc, mult, box, ball)


def used_gens(gens: tuple, *polys) -> tuple:
    """The variables of ``gens`` that some polynomial of ``polys`` uses (a nonzero exponent), in ``gens`` order:
    :func:`sospoly.minimize` solves over these alone (a variable in no polynomial is unbounded by every constraint,
    so no box holds a minimiser and certificates were lost, review 21a F5) and :func:`lifted` maps back."""
    used = set()
    for p in polys:
        p = p.with_gens(gens)
        for e in p.terms:
            used.update(k for k, v in enumerate(e) if v)
    return tuple(g for k, g in enumerate(gens) if k in used)


def lifted(res, gens: tuple, used: tuple):
    """The inverse of solving over ``used`` (:func:`used_gens`) instead of ``gens``: a :class:`sospoly.
    MinimizeResult` (or :class:`sospoly.RatioResult`) over ``used`` as one over ``gens``, every point with 0 in the
    unused variables (any value is as good: no polynomial holds them), ``gens`` the caller's; the moment matrices stay
    over ``used``."""
    pos = [gens.index(g) for g in used]

    def up(p):
        out = np.zeros(len(gens))
        out[pos] = np.asarray(p, float)
        return out
    import dataclasses

    note = f"variables {[g for g in gens if g not in used]} appear in no polynomial: solved without them (0 in the " \
           "points)"
    points = {"minimizers": tuple(up(p) for p in res.minimizers)}
    if hasattr(res, "candidates"):          # (a RatioResult has minimisers only)
        points["candidates"] = tuple(up(p) for p in res.candidates)
    return dataclasses.replace(res, gens=tuple(gens), message="; ".join(m for m in (res.message, note) if m),
                               **points)


def uncapped(res, f, eq, ineq):
    """A :class:`sospoly.MinimizeResult` ``res`` of (f, eq, ineq), not certified where the variables' balancing was
    capped (:attr:`VariableScaling.capped`: exponents beyond 2^+-200): the tolerances then act at a scale that is not
    the problem's (review 25b F4:
    min (s x)^2 - s x at s = 1e100 "optimal" at x = 0, f = 0 > -1/4; a point 14558 outside its constraint accepted
    at s = 1e70).  The lower bound stays (it is proven)."""
    if not res.optimal or not balancing([f, *eq, *ineq], f.nvars).capped:
        return res
    note = "not certified: balancing the variables needs powers of two beyond 2^+-200, so the gap and feasibility " \
           "tolerances do not act at the problem's own scale"
    return replace(res, optimal=False, message="; ".join(m for m in (res.message, note) if m))
