"""The *shape* of a Positivstellensatz certificate: which monomials each of its parts may use.

For ``min f s.t. g = 0, h >= 0`` the certificate of :mod:`sospoly.certificates.psatz` is

    u(v) = q(v) (f(v) - c) + sum_k r_k(v) g_k(v) - sum_k s_k(v) h_k(v),   u and every s_k SOS.

A :class:`CertificateShape` fixes, as pure data (exponent arrays over the program's variables):

* ``u_bases`` -- the Gram blocks of u: u = sum_j b_j(v)^T G_j b_j(v), G_j >= 0;
* ``r_supports`` -- the monomials of each equality multiplier r_k;
* ``s_bases`` -- the Gram basis of each inequality multiplier s_k.

*Any* shape gives a valid lower bound (the certificate identity still proves c <= f on the
feasible set); shapes differ in strength and size.  Constructors:

* :func:`dense_shape` -- every monomial up to the degree (the paper's certificate; SPEC §5);
* :func:`clique_shape` -- correlative sparsity with given cliques (Waki et al. 2006, Lasserre 2006):
  u is a sum of SOS polynomials in the variables of one clique each, every multiplier lives on a
  clique containing its constraint's variables; optionally *hybrid*: a dense block of low degree
  (and constant/low-degree multipliers for every constraint) beside the clique blocks, so the
  sparse certificate is never weaker than the dense certificate of that low degree;
* :func:`correlative_shape` -- cliques from the correlative-sparsity graph (chordal extension,
  :mod:`sospoly.certificates.sparsity`);
* :func:`term_shape` -- term sparsity (TSSOS, one iteration) of u's basis;
* :func:`newton_shape` -- the Newton-polytope (half-support) reduction of u's basis, for
  unconstrained programs only (Reznick 1978).

Sizes are computed in closed form before any basis is enumerated, and checked against
``max_gram_side`` (:class:`~sospoly.budget.Budget`), so a huge degree is refused at once.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from ..algebra.basis import monomials, sigma
from ..algebra.polynomial import Polynomial
from ..budget import BudgetExceeded, ProgramSize, check_deadline, estimate_size
from .sparsity import correlative_sparsity, newton_reduce, term_sparsity_blocks, variables_of

__all__ = ["u_support_of",
           "CertificateShape", "dense_shape", "clique_shape", "correlative_shape", "term_shape", "newton_shape",
           "clique_monomials", "Sparsity", "SPARSITY_KINDS", "low_block_helps"]


class Sparsity(str, enum.Enum):
    """The sparsity of a certificate: the choices of ``sparsity=`` (:func:`sospoly.minimize`,
    :func:`sospoly.build_psatz`, ``tritools.TriangulationOptions``) and the names of the certificate shapes
    (``CertificateShape.kind``).  One enum for both packages; the old strings are accepted on input
    (``Sparsity("none")`` is :attr:`DENSE`: ``"none"`` and ``"dense"`` are one choice, spelt two ways).
    ``str()`` and ``format()`` give the value, as for :class:`enum.StrEnum`."""
    AUTO = "auto"                  #: the caller picks (see :func:`sospoly.minimize`)
    DENSE = "dense"                #: the dense certificate (one Gram block per SOS term)
    CORRELATIVE = "correlative"    #: cliques of a chordal extension of the correlative-sparsity graph
    CLIQUES = "cliques"            #: cliques given by the caller (:func:`clique_shape`)
    TERM = "term"                  #: term sparsity (TSSOS)
    NEWTON = "newton"              #: the Newton-polytope basis (unconstrained programs)
    NONE = "dense"                 #: alias of :attr:`DENSE` (the spelling ``"none"``)

    @classmethod
    def _missing_(cls, value):
        return cls.DENSE if value is None or value == "none" else None

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)

    @classmethod
    def parse(cls, value, name: str = "sparsity", allowed: tuple | None = None,
              aliases: dict | None = None) -> Sparsity:
        """``value`` -- a member, its value, ``"none"`` (:attr:`DENSE`) or a key of ``aliases`` (a caller's own
        spelling of a member) -- as a member of ``allowed`` (default: every member); ValueError naming ``name`` and
        the accepted spellings otherwise."""
        allowed = tuple(cls) if allowed is None else tuple(allowed)
        aliases = dict(aliases or {})
        raw = getattr(value, "value", value)
        member = aliases.get(raw) if isinstance(raw, str) else None
        if member is None and isinstance(raw, str):
            try:
                member = cls(raw)
            except ValueError:
                member = None
        if member is None or member not in allowed:
            spelt = {m: k for k, m in reversed(list(aliases.items()))}
            spellings = [spelt.get(m, "none" if m is cls.DENSE else m.value) for m in allowed]
            raise ValueError(f"{name} must be one of {', '.join(spellings)}, got {value!r}")
        return member


#: the sparsity choices of :func:`sospoly.minimize` (``"auto"`` picks one, see there), as spelt there.
SPARSITY_KINDS = ("auto", "none", "correlative", "term", "newton")
#: the members of :data:`SPARSITY_KINDS`.
MINIMIZE_SPARSITIES = (Sparsity.AUTO, Sparsity.DENSE, Sparsity.CORRELATIVE, Sparsity.TERM, Sparsity.NEWTON)


@dataclass(frozen=True)
class CertificateShape:
    """Which monomials each part of the certificate may use (see the module docstring).

    ``cliques`` are the variable index sets of the clique blocks (empty for dense shapes) and
    ``block_clique[j]`` the clique of u's block j (-1: a dense block), for clique-wise extraction.
    """

    kind: str
    u_bases: tuple
    r_supports: tuple
    s_bases: tuple
    cliques: tuple = ()
    block_clique: tuple = ()
    low_degree: int | None = None
    #: apply the exact basis reductions of :mod:`sospoly.certificates.reduction` against the data
    facial_reduction: bool = False
    _key: bytes = field(default=b"", repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("u_bases", "r_supports", "s_bases"):
            arrs = tuple(np.ascontiguousarray(np.asarray(a, dtype=np.int64)) for a in getattr(self, name))
            for a in arrs:
                a.setflags(write=False)
            object.__setattr__(self, name, arrs)
        parts = [self.kind.encode(), repr(self.cliques).encode(), repr(self.low_degree).encode(),
                 repr(self.facial_reduction).encode()]
        for name in ("u_bases", "r_supports", "s_bases"):
            for a in getattr(self, name):
                parts += [repr(a.shape).encode(), a.tobytes()]
        object.__setattr__(self, "_key", b"|".join(parts))

    @property
    def key(self) -> bytes:
        """A hashable description (equal keys: equal shapes)."""
        return self._key

    def reduced(self) -> CertificateShape:
        """This shape with the exact basis reductions requested (:mod:`sospoly.certificates.reduction`;
        applied when a program is built from the shape and its data)."""
        from dataclasses import replace
        return replace(self, facial_reduction=True)

    @property
    def is_dense(self) -> bool:
        return self.kind == Sparsity.DENSE

    def gram_sides(self) -> tuple:
        return tuple(b.shape[0] for b in self.u_bases) + tuple(b.shape[0] for b in self.s_bases)

    def n_free(self) -> int:
        return sum(r.shape[0] for r in self.r_supports)

    def size(self, free_q_side: int = 0) -> ProgramSize:
        """The estimated size of the program (:func:`sospoly.budget.estimate_size`); ``free_q_side`` the Gram
        side of a free multiplier q."""
        sides = self.gram_sides() + ((free_q_side,) if free_q_side else ())
        return estimate_size(sides, 1 + self.n_free(), 1 if free_q_side else 0)


def _check_side(side: int, max_gram_side: int | None, what: str) -> None:
    if max_gram_side is not None and side > max_gram_side:
        def shown(k: int) -> str:
            return f"{k}" if len(str(k)) <= 12 else f"~1e{len(str(k)) - 1}"
        raise BudgetExceeded(f"{what} would have a Gram matrix of side {shown(side)} (limit {max_gram_side})",
                             hint="use a lower degree or a sparse certificate (sparsity='correlative')")


def clique_monomials(n: int, clique, degree: int) -> np.ndarray:
    """All monomials of degree <= ``degree`` in the variables ``clique`` (indices), as exponent rows over
    all ``n`` variables, in the documented order."""
    clique = np.asarray(clique, dtype=np.int64)
    if degree < 0:
        return np.zeros((0, n), np.int64)
    local = monomials(len(clique), int(degree))
    out = np.zeros((local.shape[0], n), np.int64)
    out[:, clique] = local
    return out


def _union_rows(*arrays: np.ndarray, n: int) -> np.ndarray:
    arrs = [a for a in arrays if a.shape[0]]
    if not arrs:
        return np.zeros((0, n), np.int64)
    from ..algebra.basis import graded_order, unique_rows

    u = unique_rows(np.vstack(arrs))
    return u[graded_order(u)]


def dense_shape(n: int, degree: int, eq_degrees=(), ineq_degrees=(), max_gram_side: int | None = None
                ) -> CertificateShape:
    """Every monomial up to the degree: u's basis all monomials of degree <= degree/2, deg r_k <= degree -
    deg g_k, s_k's basis of degree <= (degree - deg h_k)/2 (SPEC §5)."""
    _check_side(sigma(n, degree // 2), max_gram_side, f"the degree-{degree} certificate in {n} variables")
    u = (monomials(n, degree // 2),)
    r = tuple(monomials(n, degree - int(d)) if degree - int(d) >= 0 else np.zeros((0, n), np.int64)
              for d in eq_degrees)
    s = tuple(monomials(n, (degree - int(d)) // 2) for d in ineq_degrees)
    return CertificateShape(Sparsity.DENSE, u, r, s)


def clique_shape(n: int, degree: int, cliques, eq_variables=(), ineq_variables=(), eq_degrees=(), ineq_degrees=(),
                 *, low_degree: int | None = None, max_gram_side: int | None = None,
                 kind: str = Sparsity.CLIQUES) -> CertificateShape:
    """Correlative sparsity with the given ``cliques`` (sequences of variable indices).

    u's blocks: one per clique, all monomials of degree <= degree/2 in its variables; with
    ``low_degree`` also a dense block of degree low_degree/2 in all variables first.  A multiplier
    of constraint k lives on the smallest clique holding the constraint's variables
    (``eq_variables[k]`` / ``ineq_variables[k]``, index sets); with ``low_degree`` it also gets every
    monomial of degree <= low_degree - deg (the dense low-degree certificate's multiplier).  A
    constraint in no clique keeps only that low-degree part (none without ``low_degree``).
    """
    cliques = tuple(tuple(sorted(int(i) for i in c)) for c in cliques)
    if not cliques:
        raise ValueError("clique_shape needs at least one clique")
    for c in cliques:
        check_deadline("sizing the certificate")
        if any(i < 0 or i >= n for i in c) or len(set(c)) != len(c):
            raise ValueError(f"clique {c} is not a set of variable indices in 0..{n - 1}")
        _check_side(sigma(len(c), degree // 2), max_gram_side, f"the degree-{degree} block of a {len(c)}-variable "
                                                               f"clique")
    if low_degree is not None:
        low_degree = int(low_degree)
        if low_degree % 2 or low_degree < 0 or low_degree > degree:
            raise ValueError(f"low_degree must be even and between 0 and the degree {degree}, got {low_degree}")
        _check_side(sigma(n, low_degree // 2), max_gram_side, f"the dense degree-{low_degree} block")
    sets = [frozenset(c) for c in cliques]

    def home(vars_) -> int:
        vars_ = frozenset(int(i) for i in vars_)
        fits = [k for k, c in enumerate(sets) if vars_ <= c]
        return min(fits, key=lambda k: (len(sets[k]), k)) if fits else -1

    empty = np.zeros((0, n), np.int64)
    u, block_clique = [], []
    if low_degree is not None:
        u.append(monomials(n, low_degree // 2))
        block_clique.append(-1)
    for k, c in enumerate(cliques):
        check_deadline("sizing the certificate")
        u.append(clique_monomials(n, c, degree // 2))
        block_clique.append(k)
    r = []
    for vars_, d in zip(eq_variables, eq_degrees):
        check_deadline("sizing the certificate")
        k = home(vars_)
        local = clique_monomials(n, cliques[k], degree - int(d)) if k >= 0 else empty
        low = monomials(n, low_degree - int(d)) if low_degree is not None and low_degree >= d else empty
        r.append(_union_rows(local, low, n=n))
    s = []
    for vars_, d in zip(ineq_variables, ineq_degrees):
        check_deadline("sizing the certificate")
        k = home(vars_)
        local = clique_monomials(n, cliques[k], (degree - int(d)) // 2) if k >= 0 else empty
        low = monomials(n, (low_degree - int(d)) // 2) if low_degree is not None and low_degree >= d else empty
        s.append(_union_rows(local, low, n=n))
    return CertificateShape(kind, tuple(u), tuple(r), tuple(s), cliques, tuple(block_clique), low_degree)


def correlative_shape(f_support, eq_supports, ineq_supports, degree: int, *, low_degree: int | None = None,
                      max_gram_side: int | None = None) -> CertificateShape:
    """:func:`clique_shape` on the maximal cliques of a chordal extension of the correlative-sparsity
    graph (variables linked when they share a term of f or a constraint)."""
    f_support = np.asarray(f_support, dtype=np.int64)
    n = f_support.shape[1]
    cs = correlative_sparsity(n, f_support, tuple(eq_supports), tuple(ineq_supports))
    eq_vars = [variables_of(E) for E in eq_supports]
    ineq_vars = [variables_of(E) for E in ineq_supports]
    eq_deg = [int(np.asarray(E).sum(axis=1).max(initial=0)) for E in eq_supports]
    ineq_deg = [int(np.asarray(E).sum(axis=1).max(initial=0)) for E in ineq_supports]
    return clique_shape(n, degree, cs.cliques, eq_vars, ineq_vars, eq_deg, ineq_deg, low_degree=low_degree,
                        max_gram_side=max_gram_side, kind=Sparsity.CORRELATIVE)


def u_support_of(f_support: np.ndarray, eq_supports, ineq_supports, n: int) -> np.ndarray:
    """The monomials u is known to contain: f's, every constraint's and the constant."""
    return _union_rows(np.asarray(f_support, np.int64).reshape(-1, n), np.zeros((1, n), np.int64),
                       *[np.asarray(E, np.int64).reshape(-1, n) for E in (*eq_supports, *ineq_supports)], n=n)


def term_shape(f_support, eq_supports, ineq_supports, degree: int, *, max_gram_side: int | None = None
               ) -> CertificateShape:
    """Term sparsity (TSSOS, one iteration) of u's dense basis over the support of f, of the constraints
    and the constant; multipliers stay dense."""
    f_support = np.asarray(f_support, dtype=np.int64)
    n = f_support.shape[1]
    dense = dense_shape(n, degree, [int(np.asarray(E).sum(axis=1).max(initial=0)) for E in eq_supports],
                        [int(np.asarray(E).sum(axis=1).max(initial=0)) for E in ineq_supports], max_gram_side)
    basis = dense.u_bases[0]
    blocks = term_sparsity_blocks(u_support_of(f_support, eq_supports, ineq_supports, n), basis)
    return CertificateShape(Sparsity.TERM, tuple(basis[b] for b in blocks), dense.r_supports, dense.s_bases)


def newton_shape(f_support, degree: int, *, q_support=None, max_gram_side: int | None = None) -> CertificateShape:
    """u's basis reduced to the monomials m with 2m in the Newton polytope of supp(q f) ∪ supp(q) (for
    an unconstrained program u = q (f - c); Reznick 1978)."""
    f_support = np.asarray(f_support, dtype=np.int64)
    n = f_support.shape[1]
    dense = dense_shape(n, degree, max_gram_side=max_gram_side)
    q_support = np.zeros((1, n), np.int64) if q_support is None else np.asarray(q_support, np.int64)
    prod = (q_support[:, None, :] + f_support[None, :, :]).reshape(-1, n)
    support = _union_rows(prod, q_support, n=n)
    basis = newton_reduce(support, dense.u_bases[0])
    return CertificateShape(Sparsity.NEWTON, (basis,), (), ())


def low_block_helps(eq, ineq, multiplier) -> bool:
    """Can a dense degree-2 block beside degree >= 4 clique blocks strengthen the certificate?

    Only through a multiplier that couples variables of different cliques.  Otherwise every
    monomial x_i x_j with i, j in no common clique is produced by that block alone, so its Gram
    entry is 0: the block's Gram matrix has the chordal pattern of the cliques (with the constant
    monomial joined to all) and is, by Agler et al. (1988), a sum of PSD matrices on {1} + C_k --
    quadratic SOS in the variables of one clique, which the clique blocks already hold.  The low
    parts of the multipliers couple cliques only for an equality of degree <= 1 (r_k of degree 1
    in all variables) or a constant inequality (s_k of degree 2); a non-constant user q couples
    whatever its terms couple."""
    if isinstance(multiplier, Polynomial) and multiplier.degree > 0:
        return True
    return any(g.degree <= 1 for g in eq) or any(h.degree <= 0 for h in ineq)
