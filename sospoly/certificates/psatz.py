"""Positivstellensatz certificates for lower bounds (SPEC §5, the paper's (42)-(44)).

For ``min f(v) s.t. g(v) = 0, h(v) >= 0`` and an even degree ``delta``, search

    u(v) = q(v) (f(v) - c) + r(v)^T g(v) - s(v)^T h(v)    SOS,
    q SOS and not identically zero,  every s_k SOS,

maximising c.  Degrees follow from delta: deg r_k <= delta - deg g_k,
deg s_k <= delta - deg h_k (rounded down to even), deg q <= delta - deg f.

Multiplier choices (:class:`Multiplier`):

* ``FIXED`` -- q = (1 + ||v||^2)^k with k = floor((delta - deg f)/2) (the paper's
  (1 + ||v||^2)^(delta/2 - 1) for quadratic f): one SDP maximising c.
* a user Polynomial or positive number q -- the same SDP with that q (q = 1 is
  Putinar's certificate); a non-constant q is verified to be SOS first.
* ``FREE`` -- q a free SOS with trace(Gram(q)) = 1.  c then multiplies decision
  variables (a generalised eigenvalue problem); the program is built once with c
  as a *parameter* and solved by bisection (:mod:`sospoly.solvers.gevp`).

Any feasible certificate gives c <= f(v) on the feasible set (weak
Positivstellensatz argument of Theorem 1), so c is a valid lower bound.
This module only builds data; it imports no solver.
"""
from __future__ import annotations

import enum
import numbers
from dataclasses import dataclass

from ..algebra.basis import sigma
from ..algebra.linpoly import LinPoly
from ..algebra.polynomial import Polynomial, as_polynomial
from .program import SOSConstraint, SOSProgram

__all__ = ["Multiplier", "PsatzProblem", "build_psatz", "delta_min", "default_q", "common_gens", "MAX_GRAM_SIDE",
           "check_degree_supported"]


class Multiplier(str, enum.Enum):
    FIXED = "fixed"
    FREE = "free"


def common_gens(*polys) -> tuple[str, ...]:
    gens: tuple[str, ...] = ()
    for p in polys:
        for g in p.gens:
            if g not in gens:
                gens = gens + (g,)
    return gens


def _check_poly(p, what: str) -> Polynomial:
    if isinstance(p, Polynomial):
        return p
    if isinstance(p, numbers.Real) and not isinstance(p, bool):
        return as_polynomial(p)
    raise TypeError(f"{what} must be a sospoly Polynomial or a real number, got {type(p).__name__}")


def delta_min(f: Polynomial, eq=(), ineq=()) -> int:
    """delta_min = 2 ceil(max(deg f, deg g_k, deg h_k) / 2) (SPEC §5)."""
    d = max([f.degree] + [g.degree for g in eq] + [h.degree for h in ineq] + [0])
    return 2 * ((d + 1) // 2)


def default_q(gens, delta: int, deg_f: int) -> Polynomial:
    """(1 + ||v||^2)^k with k = floor((delta - deg f)/2)."""
    k = max((delta - max(deg_f, 0)) // 2, 0)
    norm2 = Polynomial.constant(1.0, gens)
    for g in gens:
        norm2 = norm2 + Polynomial(gens, {tuple(2 if h == g else 0 for h in gens): 1.0})
    return norm2 ** k


@dataclass(frozen=True)
class PsatzProblem:
    """The data of one Positivstellensatz program (pure data, no solver)."""

    f: Polynomial
    eq: tuple
    ineq: tuple
    gens: tuple
    degree: int
    multiplier: Multiplier
    q: Polynomial | None          # fixed q (None when free)
    program: SOSProgram
    c: LinPoly | None             # decision scalar c (fixed q)
    q_expr: LinPoly | None        # SOS q (free q)
    r: tuple
    s: tuple
    u: SOSConstraint

    @property
    def n_lmivar(self) -> int:
        return self.program.n_lmivar()


#: the largest Gram matrix side sigma(n, delta/2) = C(n + delta/2, n) a program may have.  Far beyond what the
#: solvers hold in memory (12.5M Gram entries, more equality rows); larger degrees are rejected at once
#: instead of expanding (1 + ||v||^2)^(delta/2 - 1) for hours (a problem file with "delta": 1e30 hung).
MAX_GRAM_SIDE = 5000


def check_degree_supported(nvars: int, degree: int) -> None:
    """ValueError when the degree-``degree`` program in ``nvars`` variables exceeds :data:`MAX_GRAM_SIDE`."""
    side = sigma(int(nvars), int(degree) // 2)
    if side > MAX_GRAM_SIDE:
        def shown(k: int) -> str:
            return f"{k}" if len(str(k)) <= 12 else f"~1e{len(str(k)) - 1}"
        raise ValueError(f"degree {shown(int(degree))} is not supported: its Gram matrix in {nvars} variables would "
                         f"have side {shown(side)} (limit {MAX_GRAM_SIDE})")


def _checked_inputs(f, eq, ineq, degree, gens) -> tuple:
    """(f, eq, ineq, gens, degree) validated and on common variables: the input rules of
    :func:`build_psatz` (also those of :class:`sospoly.lowering.compiled.CompiledPsatz`)."""
    f = _check_poly(f, "f")
    eq = tuple(_check_poly(g, "each equality g_k") for g in eq)
    ineq = tuple(_check_poly(h, "each inequality h_k") for h in ineq)
    if gens is None:
        gens = common_gens(f, *eq, *ineq)
    gens = tuple(gens)
    if not gens:
        raise ValueError("the problem has no variables")
    f = f.with_gens(gens)
    eq = tuple(g.with_gens(gens) for g in eq)
    ineq = tuple(h.with_gens(gens) for h in ineq)
    dmin = delta_min(f, eq, ineq)
    if degree is None:
        degree = max(dmin, 2)
    if not isinstance(degree, numbers.Integral) or isinstance(degree, bool):
        raise TypeError(f"degree must be an even integer, got {degree!r}")
    degree = int(degree)
    if degree % 2:
        raise ValueError(f"degree must be even, got {degree}")
    if degree < dmin:
        raise ValueError(f"degree {degree} is below delta_min = {dmin} for these polynomials")
    if f.degree > degree:
        raise ValueError(f"deg f = {f.degree} exceeds degree {degree}")
    check_degree_supported(len(gens), degree)
    return f, eq, ineq, gens, degree


def _as_multiplier(multiplier):
    """A multiplier given by its string value as the :class:`Multiplier`; anything else unchanged."""
    if isinstance(multiplier, str) and not isinstance(multiplier, Multiplier):
        try:
            return Multiplier(multiplier)
        except ValueError:
            raise ValueError(f"multiplier must be 'fixed', 'free', a Polynomial or a number; got {multiplier!r}") from None
    return multiplier


def _fixed_q(multiplier, gens, degree: int, f: Polynomial) -> Polynomial:
    """The fixed multiplier q: :func:`default_q` for ``Multiplier.FIXED``, else the given SOS
    polynomial or positive number (checked: not zero, deg q + deg f <= degree)."""
    if multiplier == Multiplier.FIXED:
        return default_q(gens, degree, f.degree)
    q = _check_poly(multiplier, "multiplier q").with_gens(gens) if isinstance(multiplier, Polynomial) \
        else Polynomial.constant(float(multiplier), gens)
    if q.is_zero or (q.degree == 0 and q.coefficient((0,) * len(gens)) <= 0):
        raise ValueError("a fixed multiplier q must be SOS and not identically zero (a positive number "
                         "or an SOS polynomial)")
    if q.degree + max(f.degree, 0) > degree:
        raise ValueError(f"deg q + deg f = {q.degree + f.degree} exceeds degree {degree}")
    return q


def build_psatz(f, eq=(), ineq=(), degree: int | None = None, multiplier=Multiplier.FIXED,
                gens=None) -> PsatzProblem:
    """Build the Positivstellensatz program of SPEC §5 (see module docstring)."""
    f, eq, ineq, gens, degree = _checked_inputs(f, eq, ineq, degree, gens)
    prog = SOSProgram(gens)
    c = q_expr = None
    q_fixed = None
    param_terms = {}
    multiplier = _as_multiplier(multiplier)
    if multiplier == Multiplier.FREE:
        kind = Multiplier.FREE
        qdeg = degree - max(f.degree, 0)
        q_expr = prog.sos_poly(qdeg, name="q")
        prog.add_equality(prog.gram_trace("q"), 1.0, name="trace_q")
        u = q_expr * f
        param_terms = {"c": q_expr * -1.0}
    else:
        kind = Multiplier.FIXED
        q_fixed = _fixed_q(multiplier, gens, degree, f)
        c = prog.scalar("c")
        u = LinPoly.from_polynomial(q_fixed * f, gens) - c * q_fixed
    r = []
    for k, g in enumerate(eq):
        rk = prog.free_poly(degree - g.degree, name=f"r{k}")
        u = u + rk * g
        r.append(rk)
    s = []
    for k, h in enumerate(ineq):
        sk = prog.sos_poly(degree - h.degree, name=f"s{k}")
        u = u - sk * h
        s.append(sk)
    ucon = prog.add_sos(u, degree=degree, name="u", param_terms=param_terms)
    if c is not None:
        prog.maximize(c)
    return PsatzProblem(f, eq, ineq, gens, degree, kind, q_fixed, prog, c, q_expr, tuple(r), tuple(s), ucon)
