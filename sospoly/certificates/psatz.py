"""Positivstellensatz certificates for lower bounds (SPEC §5, the paper's (42)-(44)), as pure data.

For ``min f(v) s.t. g(v) = 0, h(v) >= 0`` and an even degree ``delta``, search

    u(v) = q(v) (f(v) - c) + r(v)^T g(v) - s(v)^T h(v)    SOS,
    q SOS and not identically zero,  every s_k SOS,

maximising c.  Any feasible certificate gives c <= f(v) on the feasible set (the weak
Positivstellensatz argument of Theorem 1), so c is a valid lower bound.

Three layers, each pure data (no solver is imported here):

* :class:`DataSlots` -- the *numbers* of an instance: the coefficient vector
  theta = (coef f, coef g_1, ..., coef h_m) over fixed supports, with a public way to address
  every slot (:meth:`DataSlots.index`) and to read an instance's theta (:meth:`DataSlots.theta`);
* :class:`PsatzStructure` -- *what* certificate is sought for every instance of those supports:
  the degree, the multiplier q, the certificate's shape (:mod:`.shape`: dense, or sparse) and the
  SOS program in which theta enters as parameters (so it is lowered once and re-filled per
  instance, :mod:`sospoly.lowering.compiled`);
* :class:`PsatzProblem` -- a structure and one instance's theta (what :func:`build_psatz` returns).

Multiplier choices (:class:`Multiplier`):

* ``FIXED`` -- for dense certificates q = (1 + ||v||^2)^k with k = floor((delta - deg f)/2) (the
  paper's (1 + ||v||^2)^(delta/2 - 1) for quadratic f); for sparse certificates q = 1 (Putinar's
  certificate: (1 + ||v||^2)^k couples every variable with every other and no clique-wise
  certificate can match it).  One SDP maximising c.
* a user Polynomial or positive number q -- the same SDP with that q (q = 1 is Putinar's
  certificate); :func:`sospoly.minimize` checks a non-constant q is SOS first.
* ``FREE`` -- q a free SOS with trace(Gram(q)) = 1 (dense shapes only).  c then multiplies
  decision variables (a generalised eigenvalue problem); c enters the program as a parameter and
  the bisection of :mod:`sospoly.solvers.gevp` moves it.

Parameters of the program (lowered once, see :mod:`sospoly.lowering.compiled`): ``f:t`` for term t
of f (q m_t, or q_free m_t), ``m:t`` for the t-th term *slot* of every constrained polynomial
together (sum_k mult_k m_{k,t}, mult_k = r_k or -s_k: the multipliers own disjoint columns, so
each slot's matrix splits by column block into one matrix per theta entry), and ``c`` (free q).
"""
from __future__ import annotations

import enum
import numbers
from dataclasses import dataclass, field

import numpy as np

from ..algebra.basis import MonomialIndex, monomials, sigma
from ..algebra.linpoly import LinPoly
from ..algebra.polynomial import Polynomial, as_polynomial, checked_gens
from ..budget import BudgetExceeded, check_deadline, check_time_left
from .program import SOSConstraint, SOSProgram
from .q_check import check_q_not_evidently_negative
from .shape import CertificateShape, correlative_shape, dense_shape, newton_shape
from .term_hierarchy import parse_term_kind, term_level_shape
from .reduction import reduce_shape
from .sizing import check_size

__all__ = ["Multiplier", "DataSlots", "PsatzStructure", "PsatzProblem", "StructureMismatch", "build_psatz",
           "psatz_structure", "delta_min", "default_q", "common_gens", "checked_inputs", "as_multiplier",
           "MAX_GRAM_SIDE", "check_degree_supported", "certificate_shape", "check_size"]


class Multiplier(str, enum.Enum):
    """The multiplier q of the Positivstellensatz certificate (see the module docstring)."""
    FIXED = "fixed"          #: q = (1 + ||v||^2)^k for dense certificates, 1 for sparse ones
    PUTINAR = "putinar"      #: q = 1 (Putinar's certificate)
    FREE = "free"            #: q a free SOS with unit trace (GEVP)


class StructureMismatch(ValueError):
    """An instance does not fit a structure's data slots (names what differs)."""


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
    """delta_min = 2 ceil(max(deg f, deg g_k, deg h_k) / 2) (SPEC §5).  Checks the active deadline every
    :data:`DEADLINE_STRIDE` polynomials (tens of thousands of constraints take seconds to read)."""
    d = 0
    for k, p in enumerate((f, *eq, *ineq)):
        if k % DEADLINE_STRIDE == 0:
            check_deadline("reading the data's degrees")
        d = max(d, p.degree)
    return 2 * ((d + 1) // 2)


#: polynomials read between two deadline checks in :func:`delta_min`.
DEADLINE_STRIDE = 64


def default_q(gens, delta: int, deg_f: int) -> Polynomial:
    """(1 + ||v||^2)^k with k = floor((delta - deg f)/2); ``delta`` and ``deg_f`` integers (TypeError naming them
    otherwise, also where k would be 0)."""
    for name, value in (("delta", delta), ("deg_f", deg_f)):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
            raise TypeError(f"default_q: {name} must be an integer, got {value!r}")
    k = max((int(delta) - max(int(deg_f), 0)) // 2, 0)
    n = len(gens)
    if k == 0:
        return Polynomial.constant(1.0, gens)
    terms = {(0,) * n: 1.0}                  # 1 + sum_j v_j^2 in one dictionary (not n sums of growing ones)
    for j in range(n):
        terms[(0,) * j + (2,) + (0,) * (n - j - 1)] = 1.0
    return Polynomial._raw(tuple(str(g) for g in gens), terms) ** k


#: the largest Gram matrix side sigma(n, delta/2) = C(n + delta/2, n) a dense program may have (the default
#: of :class:`sospoly.Budget`'s ``max_gram_side``): larger degrees are refused at once instead of expanding
#: (1 + ||v||^2)^(delta/2 - 1) for hours.
MAX_GRAM_SIDE = 5000


def check_degree_supported(nvars: int, degree: int, max_gram_side: int = MAX_GRAM_SIDE) -> None:
    """:class:`~sospoly.budget.BudgetExceeded` (a ValueError) when the dense degree-``degree`` program in
    ``nvars`` variables has a Gram matrix larger than ``max_gram_side``."""
    side = sigma(int(nvars), int(degree) // 2)
    if side > max_gram_side:
        def shown(k: int) -> str:
            return f"{k}" if len(str(k)) <= 12 else f"~1e{len(str(k)) - 1}"
        raise BudgetExceeded(f"degree {shown(int(degree))} is not supported: its Gram matrix in {nvars} variables "
                             f"would have side {shown(side)} (limit {max_gram_side})",
                             hint="use a lower degree or a sparse certificate")


def _sequence(polys, name: str):
    """``polys`` as a sequence of constraints; one polynomial or number (not a sequence) is a TypeError naming the
    argument (``eq=g`` for ``eq=[g]``)."""
    if isinstance(polys, (Polynomial, numbers.Number, str)) or not hasattr(polys, "__iter__"):
        raise TypeError(f"{name} must be a sequence of polynomials, e.g. {name}=[g], got a single "
                        f"{type(polys).__name__}")
    return polys


def checked_inputs(f, eq, ineq, degree, gens, max_gram_side: int | None = MAX_GRAM_SIDE) -> tuple:
    """(f, eq, ineq, gens, degree) validated and on common variables: the input rules of every
    Positivstellensatz entry point."""
    f = _check_poly(f, "f")
    eq = tuple(_check_poly(g, "each equality g_k") for g in _sequence(eq, "eq"))
    ineq = tuple(_check_poly(h, "each inequality h_k") for h in _sequence(ineq, "ineq"))
    if gens is None:
        gens = common_gens(f, *eq, *ineq)
    gens = checked_gens(gens)
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
    if max_gram_side is not None and len(str(degree)) > 6:
        check_degree_supported(len(gens), degree, max_gram_side)      # absurd degrees: refused before any work
    return f, eq, ineq, gens, degree


def as_multiplier(multiplier):
    """A multiplier given by its string value as the :class:`Multiplier`; numbers and Polynomials unchanged."""
    if isinstance(multiplier, Multiplier):
        return multiplier
    if isinstance(multiplier, str):
        try:
            return Multiplier(multiplier)
        except ValueError:
            raise ValueError(f"multiplier must be 'fixed', 'putinar', 'free', a Polynomial or a number; got "
                             f"{multiplier!r}") from None
    if isinstance(multiplier, Polynomial) or (isinstance(multiplier, numbers.Real)
                                              and not isinstance(multiplier, bool)):
        return multiplier
    raise TypeError(f"multiplier must be 'fixed', 'free', a Polynomial or a positive number, got "
                    f"{type(multiplier).__name__}")


def _fixed_q(multiplier, gens, degree: int, f: Polynomial, dense: bool) -> Polynomial:
    """The fixed multiplier q (see the module docstring), checked: not zero, deg q + deg f <= degree."""
    if multiplier == Multiplier.FIXED:
        return default_q(gens, degree, f.degree) if dense else Polynomial.constant(1.0, gens)
    if multiplier == Multiplier.PUTINAR:
        return Polynomial.constant(1.0, gens)
    q = _check_poly(multiplier, "multiplier q").with_gens(gens) if isinstance(multiplier, Polynomial) \
        else Polynomial.constant(float(multiplier), gens)
    if q.is_zero or (q.degree == 0 and q.coefficient((0,) * len(gens)) <= 0):
        raise ValueError("a fixed multiplier q must be SOS and not identically zero (a positive number "
                         "or an SOS polynomial)")
    check_q_not_evidently_negative(q)
    if q.degree + max(f.degree, 0) > degree:
        raise ValueError(f"deg q + deg f = {q.degree + f.degree} exceeds degree {degree}")
    return q


def _support(p: Polynomial) -> np.ndarray:
    check_deadline("reading the data's supports")
    E = p.exponents()
    return E[np.lexsort(E.T[::-1])] if E.shape[0] else E


# ----------------------------------------------------------------------------- data slots
#: CPU seconds per entry (exponent rows x (variables + 1)) of the stacked supports when they are indexed
#: (:class:`DataSlots`: the stack, its polynomial column and the sorted index, one native call each) or an
#: instance's coefficients are looked up in them (:meth:`DataSlots.theta`).  Measured ~1e-7 under a load
#: average of 7 on 2 cores (Corollary 1 with 50 / 100 disc regions: 1.2e6 / 1.4e7 entries, 0.12 / 1.3 s).
INDEX_SECONDS_PER_ENTRY = 5e-8


def _index_seconds(rows: int, n_vars: int) -> float:
    """Predicted CPU seconds of indexing ``rows`` exponent rows of ``n_vars`` variables (not interruptible:
    :func:`sospoly.budget.check_time_left` does not start it when it cannot end before the deadline)."""
    return INDEX_SECONDS_PER_ENTRY * float(rows) * float(n_vars + 1)


@dataclass(frozen=True)
class DataSlots:
    """The layout of theta = (coef f, coef g_1, ..., coef g_K, coef h_1, ..., coef h_M).

    ``supports[p]`` are the exponent rows of polynomial p (0 = f, then the equalities, then the
    inequalities), sorted; theta[offsets[p] + t] is the coefficient of supports[p][t].
    """

    gens: tuple
    supports: tuple
    degrees: tuple
    n_eq: int
    n_ineq: int
    _index: MonomialIndex = field(repr=False, compare=False, default=None)

    def __post_init__(self) -> None:
        n = len(self.gens)
        sup = tuple(np.ascontiguousarray(np.asarray(E, np.int64).reshape(-1, n)) for E in self.supports)
        object.__setattr__(self, "supports", sup)
        if len(sup) != 1 + self.n_eq + self.n_ineq:
            raise ValueError("DataSlots: one support per polynomial (f, equalities, inequalities)")
        check_time_left(_index_seconds(sum(E.shape[0] for E in sup), n), "indexing the data's supports")
        ids = np.repeat(np.arange(len(sup)), [E.shape[0] for E in sup])
        stacked = np.vstack(sup) if sum(E.shape[0] for E in sup) else np.zeros((0, n), np.int64)
        object.__setattr__(self, "_index", MonomialIndex(np.hstack([ids[:, None], stacked])))

    @classmethod
    def of(cls, f: Polynomial, eq=(), ineq=(), gens=None) -> DataSlots:
        """The slots of the polynomials' own supports."""
        gens = tuple(gens if gens is not None else common_gens(f, *eq, *ineq))
        polys = (f,) + tuple(eq) + tuple(ineq)
        return cls(gens, tuple(_support(p.with_gens(gens)) for p in polys), tuple(p.degree for p in polys),
                   len(eq), len(ineq))

    @property
    def offsets(self) -> np.ndarray:
        return np.concatenate([[0], np.cumsum([E.shape[0] for E in self.supports])]).astype(np.int64)

    @property
    def n_theta(self) -> int:
        return int(self.offsets[-1])

    def name(self, which: int) -> str:
        """``"f"``, ``"eq[k]"`` or ``"ineq[k]"`` for polynomial ``which``."""
        return "f" if which == 0 else (f"eq[{which - 1}]" if which <= self.n_eq else f"ineq[{which - 1 - self.n_eq}]")

    def _which(self, which) -> int:
        if isinstance(which, str):
            names = [self.name(p) for p in range(len(self.supports))]
            if which not in names:
                raise KeyError(f"no polynomial {which!r} (have {', '.join(names)})")
            return names.index(which)
        return int(which)

    def index(self, which, exponents) -> np.ndarray:
        """Positions in theta of the given exponent rows of polynomial ``which`` (an int or a name such as
        ``"eq[2]"``); -1 where a row is not in that polynomial's support."""
        p = self._which(which)
        E = np.asarray(exponents, np.int64).reshape(-1, len(self.gens))
        return self._index.find(np.hstack([np.full((E.shape[0], 1), p), E]), missing_ok=True)

    def key(self) -> tuple:
        return (self.gens, self.n_eq, self.n_ineq, self.degrees, tuple(E.tobytes() for E in self.supports))

    def contains(self, other: DataSlots) -> bool:
        """Does every support of ``other`` (same variables and counts) lie in this one's?"""
        if other.gens != self.gens or other.n_eq != self.n_eq or other.n_ineq != self.n_ineq:
            return False
        return all(np.all(self.index(p, E) >= 0) for p, E in enumerate(other.supports))

    def union(self, other: DataSlots) -> DataSlots:
        sup = []
        for a, b in zip(self.supports, other.supports):
            u = np.unique(np.vstack([a, b]), axis=0)
            sup.append(u[np.lexsort(u.T[::-1])] if u.shape[0] else u)
        return DataSlots(self.gens, tuple(sup), self.degrees, self.n_eq, self.n_ineq)

    def theta(self, f, eq=(), ineq=()) -> np.ndarray:
        """The coefficient vector of an instance (raises :class:`StructureMismatch` when a polynomial has
        other variables, another degree, or a term outside the support)."""
        eq, ineq = tuple(eq), tuple(ineq)
        if len(eq) != self.n_eq or len(ineq) != self.n_ineq:
            raise StructureMismatch(f"the structure has {self.n_eq} equalities and {self.n_ineq} inequalities; "
                                    f"the instance has {len(eq)} and {len(ineq)}")
        check_time_left(_index_seconds(sum(len(p.terms) for p in (f,) + eq + ineq if isinstance(p, Polynomial)),
                                       len(self.gens)), "reading the data's coefficients")
        Es, cs, ids = [], [], []
        for pi, p in enumerate((f,) + eq + ineq):
            what = self.name(pi)
            if not isinstance(p, Polynomial):
                raise TypeError(f"{what} must be a sospoly Polynomial, got {type(p).__name__}")
            if p.gens != self.gens:
                try:
                    p = p.with_gens(self.gens)
                except (ValueError, KeyError) as exc:
                    raise StructureMismatch(f"{what} has variables {p.gens}, the structure {self.gens}") from exc
            if p.degree != self.degrees[pi] and not p.is_zero:
                raise StructureMismatch(f"{what} has degree {p.degree}, the structure {self.degrees[pi]}")
            Es.append(p.exponents())
            cs.append(p.coefficients())
            ids.append(np.full(len(p.terms), pi))
        E = np.hstack([np.concatenate(ids)[:, None], np.vstack(Es)])
        idx = self._index.find(E, missing_ok=True)
        if np.any(idx < 0):
            bad = E[np.argmax(idx < 0)]
            raise StructureMismatch(f"{self.name(int(bad[0]))} has a term with exponent "
                                    f"{tuple(int(k) for k in bad[1:])} outside the structure's support")
        th = np.zeros(self.n_theta)
        th[idx] = np.concatenate(cs)
        return th

    def polynomials(self, theta) -> tuple:
        """(f, eq, ineq) of a coefficient vector (the inverse of :meth:`theta`)."""
        polys = self._polynomials(theta, range(len(self.supports)))
        return polys[0], tuple(polys[1:1 + self.n_eq]), tuple(polys[1 + self.n_eq:])

    def ineq_polynomials(self, theta) -> tuple:
        """The inequalities alone of :meth:`polynomials` (a 30-view program has ~450 equalities and a few
        inequalities: building every polynomial to read these took ~0.8 s)."""
        return tuple(self._polynomials(theta, range(1 + self.n_eq, len(self.supports))))

    def _polynomials(self, theta, parts) -> list:
        th = np.asarray(theta, float)
        off = self.offsets
        return [Polynomial(self.gens, {tuple(int(k) for k in e): float(c)
                                       for e, c in zip(self.supports[p], th[off[p]:off[p + 1]]) if c != 0.0})
                for p in parts]


# ----------------------------------------------------------------------------- the structure
@dataclass(frozen=True, eq=False)
class PsatzStructure:
    """What certificate is sought for every instance of some data slots (see the module docstring).

    ``program`` holds the decision blocks (``c`` or the free ``q``, ``r{k}``, ``s{k}``) and the SOS
    constraint ``u`` whose data enter as parameters; ``free`` tells whether q is free (then ``c`` is a
    parameter: the GEVP level)."""

    slots: DataSlots
    degree: int
    free: bool
    q: Polynomial | None
    shape: CertificateShape
    program: SOSProgram
    u: SOSConstraint
    key: tuple
    q_expr: LinPoly | None = None       # the free multiplier's polynomial in the decision variables
    r: tuple = ()                       # the equality multipliers r_k (polynomials in the decision variables)
    s: tuple = ()                       # the inequality multipliers s_k (SOS, in the decision variables)

    @property
    def gens(self) -> tuple:
        return self.slots.gens

    @property
    def multiplier(self) -> Multiplier:
        return Multiplier.FREE if self.free else Multiplier.FIXED

    @property
    def n_lmivar(self) -> int:
        return self.program.n_lmivar()


def _mono(gens, e) -> Polynomial:
    return Polynomial(gens, {tuple(int(k) for k in e): 1.0})


#: rows of f's support between two deadline checks while its slots are assembled (one row is one small product)
_DEADLINE_ROWS = 64


def _multipliers(prog: SOSProgram, shape: CertificateShape) -> tuple:
    """(r, s, the multipliers of the equality and inequality slots): the free r_k on the supports of
    ``shape.r_supports``, the SOS s_k on the bases ``shape.s_bases``, and (r_1, ..., r_K, -s_1, ..., -s_M).
    The active deadline is checked before each one: a dense program of 100 views with disc regions has ~5,000
    equality multipliers (~2.5 ms each, seconds in all)."""
    r, s_ = [], []
    for k, E in enumerate(shape.r_supports):
        check_deadline("assembling the certificate's multipliers")
        r.append(prog.free_poly(-1, name=f"r{k}", monomial_exponents=E))
    for k, B in enumerate(shape.s_bases):
        check_deadline("assembling the certificate's multipliers")
        s_.append(prog.sos_poly(-1, name=f"s{k}", basis=B))
    neg = []
    for sk in s_:
        check_deadline("assembling the certificate's multipliers")
        neg.append(-1.0 * sk)
    return tuple(r), tuple(s_), r + neg


def psatz_structure(slots: DataSlots, degree: int, shape: CertificateShape, q: Polynomial | None) -> PsatzStructure:
    """Build the parametric program of ``slots`` with certificate ``shape``; ``q`` the fixed multiplier,
    or None for a free SOS q (dense shapes only)."""
    gens = slots.gens
    n = len(gens)
    if len(shape.r_supports) != slots.n_eq or len(shape.s_bases) != slots.n_ineq:
        raise ValueError("the certificate shape does not match the number of constraints")
    if shape.facial_reduction:
        eqs, ineqs = slots.supports[1:1 + slots.n_eq], slots.supports[1 + slots.n_eq:]
        if q is None:
            shape = reduce_shape(shape, slots.supports[0], eqs, ineqs,
                                 q_basis=monomials(n, (degree - max(slots.degrees[0], 0)) // 2))
        else:
            shape = reduce_shape(shape, slots.supports[0], eqs, ineqs, q_support=_support(q))
    prog = SOSProgram(gens)
    params = {}
    if q is None:
        if not shape.is_dense:
            raise ValueError("a free multiplier q needs a dense certificate (sparsity='none')")
        qdeg = degree - max(slots.degrees[0], 0)
        mult_q = prog.sos_poly(qdeg, name="q", basis=monomials(n, qdeg // 2))
        prog.add_equality(prog.gram_trace("q"), 1.0, name="trace_q")
        params["c"] = mult_q * -1.0
        u0 = LinPoly.from_polynomial(Polynomial(gens, {}), gens)
    else:
        c = prog.scalar("c")
        mult_q = LinPoly.from_polynomial(q, gens)
        u0 = -1.0 * (c * q)
    r, s_, mults = _multipliers(prog, shape)
    for t, e in enumerate(slots.supports[0]):
        if t % _DEADLINE_ROWS == 0:
            check_deadline("assembling the certificate")
        params[f"f:{t}"] = mult_q * _mono(gens, e)
    n_slots = max([E.shape[0] for E in slots.supports[1:]], default=0)
    for t in range(n_slots):
        check_deadline("assembling the certificate")
        # sum_k mult_k m_{k,t}: shifting a LinPoly's exponents by a monomial keeps its rows distinct,
        # so the parts are concatenated and merged once
        Es, cs, rs, cl, vs, off = [], [], [], [], [], 0
        for pi in range(1, len(slots.supports)):
            if t >= slots.supports[pi].shape[0]:
                continue
            M, e = mults[pi - 1], slots.supports[pi][t]
            Es.append(M.E + e), cs.append(M.const), rs.append(M.rows + off), cl.append(M.cols), vs.append(M.vals)
            off += M.E.shape[0]
        params[f"m:{t}"] = LinPoly(gens, np.vstack(Es).reshape(-1, n), np.concatenate(cs), np.concatenate(rs),
                                   np.concatenate(cl), np.concatenate(vs))
    check_deadline("assembling the certificate")
    u = prog.add_sos(u0, name="u", param_terms=params, bases=shape.u_bases)
    check_deadline("assembling the certificate")
    if q is not None:
        prog.maximize(c)
    qkey = None if q is None else tuple(sorted(q.terms.items()))
    key = (slots.key(), int(degree), qkey, shape.key)
    return PsatzStructure(slots, int(degree), q is None, q, shape, prog, u, key, mult_q if q is None else None, r, s_)


def certificate_shape(sparsity, gens, degree: int, f: Polynomial, eq=(), ineq=(), *, low_degree: int | None = None,
                      max_gram_side: int | None = MAX_GRAM_SIDE) -> CertificateShape:
    """The shape for a sparsity choice: ``"none"`` (dense), ``"correlative"``, ``"term"``, ``"newton"``
    (unconstrained programs), or a :class:`~sospoly.certificates.shape.CertificateShape` itself."""
    if isinstance(sparsity, CertificateShape):
        return sparsity
    n = len(gens)
    eq_deg = [g.degree for g in eq]
    ineq_deg = [h.degree for h in ineq]
    if sparsity in ("none", "dense", None):
        return dense_shape(n, degree, eq_deg, ineq_deg, max_gram_side)
    fs = _support(f) if f.terms else np.zeros((1, n), np.int64)
    if sparsity == "correlative":
        return correlative_shape(fs, [_support(g) for g in eq], [_support(h) for h in ineq], degree,
                                 low_degree=low_degree, max_gram_side=max_gram_side)
    if parse_term_kind(sparsity) is not None:          # "term" or a level "term:<completion>:<steps>"
        return term_level_shape(fs, [_support(g) for g in eq], [_support(h) for h in ineq], degree, sparsity,
                                max_gram_side=max_gram_side)
    if sparsity == "newton":
        if eq or ineq:
            raise ValueError("sparsity='newton' (the Newton-polytope basis) applies to unconstrained programs only")
        return newton_shape(fs, degree, max_gram_side=max_gram_side)
    raise ValueError(f"sparsity must be 'none', 'correlative', 'term', 'newton' or a CertificateShape, "
                     f"got {sparsity!r}")


@dataclass(frozen=True, eq=False)
class PsatzProblem:
    """A :class:`PsatzStructure` and one instance's numbers (``theta`` in its slots)."""

    structure: PsatzStructure
    theta: np.ndarray
    f: Polynomial
    eq: tuple
    ineq: tuple

    @property
    def gens(self) -> tuple:
        return self.structure.gens

    @property
    def degree(self) -> int:
        return self.structure.degree

    @property
    def multiplier(self) -> Multiplier:
        return self.structure.multiplier

    @property
    def q(self) -> Polynomial | None:
        return self.structure.q

    @property
    def shape(self) -> CertificateShape:
        return self.structure.shape

    @property
    def program(self) -> SOSProgram:
        return self.structure.program

    @property
    def u(self) -> SOSConstraint:
        return self.structure.u

    @property
    def q_expr(self) -> LinPoly | None:
        """The free multiplier q as a polynomial in the decision variables (None for a fixed q)."""
        return self.structure.q_expr

    @property
    def r(self) -> tuple:
        """The equality multipliers r_k in the decision variables (``solution.value(r[k])`` gives one)."""
        return self.structure.r

    @property
    def s(self) -> tuple:
        """The inequality multipliers s_k in the decision variables."""
        return self.structure.s

    @property
    def n_lmivar(self) -> int:
        return self.structure.n_lmivar


def build_psatz(f, eq=(), ineq=(), degree: int | None = None, multiplier=Multiplier.FIXED, gens=None, *,
                sparsity="none", low_degree: int | None = None, budget=None) -> PsatzProblem:
    """Build the Positivstellensatz program of SPEC §5 (see module docstring) for one instance.

    ``sparsity``: ``"none"`` (the dense certificate), ``"correlative"`` (clique-wise blocks; with
    ``low_degree`` also the dense certificate of that degree), ``"term"``, ``"newton"``, or a
    :class:`~sospoly.certificates.shape.CertificateShape`.  ``budget`` (:class:`sospoly.Budget`, default
    :data:`sospoly.budget.DEFAULT_BUDGET`): programs whose estimated size does not fit are refused with
    :class:`~sospoly.budget.BudgetExceeded` before anything is assembled.
    """
    from ..budget import as_budget

    budget = as_budget(budget)
    f, eq, ineq, gens, degree = checked_inputs(f, eq, ineq, degree, gens, budget.max_gram_side)
    multiplier = as_multiplier(multiplier)
    shape = certificate_shape(sparsity, gens, degree, f, eq, ineq, low_degree=low_degree,
                              max_gram_side=budget.max_gram_side)
    q = None if multiplier == Multiplier.FREE else _fixed_q(multiplier, gens, degree, f, shape.is_dense)
    if q is None and f.degree > degree:
        raise ValueError(f"deg f = {f.degree} exceeds degree {degree}")
    check_size(shape, budget, q is None, len(gens), degree, f.degree)
    slots = DataSlots.of(f, eq, ineq, gens)
    structure = psatz_structure(slots, degree, shape, q)
    return PsatzProblem(structure, slots.theta(f, eq, ineq), f, eq, ineq)


def fixed_q_for(multiplier, gens, degree: int, f: Polynomial, dense: bool = True) -> Polynomial | None:
    """The q of a fixed multiplier (None for ``"free"``): the rule of :func:`build_psatz`, for callers that
    build structures themselves (e.g. compiled caches)."""
    multiplier = as_multiplier(multiplier)
    return None if multiplier == Multiplier.FREE else _fixed_q(multiplier, gens, degree, f, dense)


__all__ += ["fixed_q_for"]
