"""SOS programs as pure data: *what* certificate is sought, not how it is solved.

An :class:`SOSProgram` owns a vector x of scalar decision variables, grouped in
named blocks:

* ``scalar(name)``: one free scalar;
* ``free_poly(degree)``: a polynomial with one free coefficient per monomial of
  degree <= ``degree`` (the multipliers r_k of the Positivstellensatz);
* ``sos_poly(degree)``: an SOS polynomial b_d(v)^T S b_d(v), S = S^T >= 0,
  parametrised by the upper-triangular entries of S (the multipliers s_k, q).

Constraints: ``add_sos(u)`` -- the polynomial u, affine in x, is SOS, with its
Gram basis chosen from its degree; ``add_equality(expr, rhs)`` -- linear
equalities on x.  An objective is a scalar (degree-0) affine expression.

Lowering to a conic problem lives in :mod:`sospoly.lowering.conic`; solving in
:mod:`sospoly.solvers.solve`.  Nothing here imports a solver.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from ..algebra.basis import GramBasis, GramBlocks, monomials
from ..algebra.linpoly import LinPoly
from ..algebra.polynomial import Polynomial, as_polynomial

__all__ = ["SOSProgram", "Sense", "VarBlock", "SOSConstraint", "EqualityConstraint"]


class Sense(str, enum.Enum):
    """Objective sense of an :class:`SOSProgram`."""
    MINIMIZE = "minimize"
    MAXIMIZE = "maximize"
    FEASIBILITY = "feasibility"


class BlockKind(str, enum.Enum):
    SCALAR = "scalar"
    FREE_POLY = "free_poly"
    SOS_POLY = "sos_poly"   # Gram entries (upper triangle, svec pair order); PSD-constrained


@dataclass(frozen=True)
class VarBlock:
    name: str
    kind: BlockKind
    start: int
    size: int
    monomials: np.ndarray | None = None       # FREE_POLY: exponents; SOS_POLY: Gram basis b
    gram: GramBasis | None = None             # SOS_POLY only

    @property
    def slice(self) -> slice:
        return slice(self.start, self.start + self.size)


@dataclass(frozen=True)
class SOSConstraint:
    """``expr + sum_k param_terms[k] * theta_k`` is SOS: a sum of ``b_j^T G_j b_j`` over the Gram
    blocks ``gram`` (:class:`~sospoly.algebra.basis.GramBlocks`; one block for a dense certificate).

    ``param_terms`` lets a scalar parameter (e.g. the level c of a GEVP) enter the
    data without rebuilding the program: the lowered problem is affine in it.
    """

    name: str
    expr: LinPoly
    gram: GramBlocks
    param_terms: dict = field(default_factory=dict)

    def block_names(self) -> tuple:
        """Names of the Gram blocks in solutions: the constraint's name for one block, else name#j."""
        k = len(self.gram.blocks)
        return (self.name,) if k == 1 else tuple(f"{self.name}#{j}" for j in range(k))


@dataclass(frozen=True)
class EqualityConstraint:
    name: str
    expr: LinPoly      # degree-0 (scalar) affine expressions, one per row
    rhs: np.ndarray


class SOSProgram:
    """A sum-of-squares program over the polynomial ring in ``gens``."""

    def __init__(self, gens):
        gens = tuple(gens.gens if isinstance(gens, Polynomial) else gens)
        if not gens:
            raise ValueError("an SOS program needs at least one polynomial variable")
        self.gens = gens
        self.n_vars = 0
        self.blocks: list[VarBlock] = []
        self.sos_constraints: list[SOSConstraint] = []
        self.equalities: list[EqualityConstraint] = []
        self.objective: LinPoly | None = None
        self.sense: Sense = Sense.FEASIBILITY

    @property
    def nvars_poly(self) -> int:
        return len(self.gens)

    def _new_block(self, name, kind, size, **kw) -> VarBlock:
        name = name or f"{kind.value}{len(self.blocks)}"
        if any(b.name == name for b in self.blocks):
            raise ValueError(f"a decision block named {name!r} already exists")
        block = VarBlock(name, kind, self.n_vars, size, **kw)
        self.blocks.append(block)
        self.n_vars += size
        return block

    def block(self, name: str) -> VarBlock:
        for b in self.blocks:
            if b.name == name:
                return b
        raise KeyError(name)

    # ------------------------------------------------------------------ decision variables
    def scalar(self, name: str | None = None) -> LinPoly:
        blk = self._new_block(name, BlockKind.SCALAR, 1)
        return LinPoly.variable_terms(self.gens, np.zeros((1, self.nvars_poly), np.int64), [blk.start])

    def free_poly(self, degree: int, name: str | None = None, monomial_exponents=None) -> LinPoly:
        """A polynomial with free coefficients on all monomials of degree <= ``degree``."""
        if monomial_exponents is None:
            if degree < 0:
                raise ValueError(f"free polynomial degree must be >= 0, got {degree}")
            E = monomials(self.nvars_poly, int(degree))
        else:
            E = np.asarray(monomial_exponents, dtype=np.int64).reshape(-1, self.nvars_poly)
        blk = self._new_block(name, BlockKind.FREE_POLY, E.shape[0], monomials=E)
        return LinPoly.variable_terms(self.gens, E, np.arange(blk.start, blk.start + blk.size))

    def sos_poly(self, degree: int, name: str | None = None, basis=None) -> LinPoly:
        """An SOS polynomial b(v)^T S b(v): b all monomials of degree <= ``degree`` / 2 (rounded down),
        or the exponent rows ``basis`` when given (then ``degree`` is ignored)."""
        if basis is not None:
            gb = GramBasis.from_exponents(np.asarray(basis, dtype=np.int64).reshape(-1, self.nvars_poly))
        else:
            if degree < 0:
                raise ValueError(f"SOS polynomial degree must be >= 0, got {degree}")
            gb = GramBasis.full(self.nvars_poly, int(degree) // 2)
        npairs = gb.n_pairs
        blk = self._new_block(name, BlockKind.SOS_POLY, npairs, monomials=gb.b, gram=gb)
        # coefficient of monomial m: sum over pairs (i<=j) with b_i b_j = m of w_ij S_ij, w = 1 (i=j) or 2
        w = np.where(gb.pair_i == gb.pair_j, 1.0, 2.0)
        return LinPoly(self.gens, gb.products, np.zeros(gb.products.shape[0]),
                       gb.pair_monomial, np.arange(blk.start, blk.start + npairs), w)

    def gram_trace(self, block_name: str) -> LinPoly:
        """trace(S) of an SOS block, as a scalar expression."""
        blk = self.block(block_name)
        if blk.kind != BlockKind.SOS_POLY:
            raise ValueError(f"block {block_name!r} is not an SOS polynomial")
        diag = np.nonzero(blk.gram.pair_i == blk.gram.pair_j)[0]
        return LinPoly(self.gens, np.zeros((1, self.nvars_poly), np.int64), [0.0],
                       np.zeros(diag.size, np.int64), blk.start + diag, np.ones(diag.size))

    # ------------------------------------------------------------------ constraints
    def add_sos(self, expr, degree: int | None = None, name: str | None = None, param_terms=None,
                bases=None) -> SOSConstraint:
        """Require ``expr`` (+ parameter terms) to be SOS: with the full Gram basis of half-degree
        degree/2, or as a sum of SOS polynomials in the given Gram ``bases`` (a sequence of exponent
        arrays: a sparse certificate; monomials of ``expr`` outside every block's products must vanish)."""
        expr = self._as_linpoly(expr)
        param_terms = {k: self._as_linpoly(v) for k, v in (param_terms or {}).items()}
        if bases is not None:
            blocks = GramBlocks.of([np.asarray(b, dtype=np.int64).reshape(-1, self.nvars_poly) for b in bases])
        else:
            deg = max([expr.degree] + [p.degree for p in param_terms.values()])
            if degree is None:
                degree = deg + (deg % 2)
            if degree % 2:
                raise ValueError(f"an SOS constraint needs an even degree, got {degree}")
            if deg > degree:
                raise ValueError(f"polynomial of degree {deg} cannot be SOS of degree <= {degree}")
            blocks = GramBlocks.of(GramBasis.full(self.nvars_poly, max(degree, 0) // 2))
        con = SOSConstraint(name or f"sos{len(self.sos_constraints)}", expr, blocks, param_terms)
        self.sos_constraints.append(con)
        return con

    def add_equality(self, expr, rhs: float = 0.0, name: str | None = None) -> EqualityConstraint:
        expr = self._as_linpoly(expr)
        if expr.degree > 0:
            raise ValueError("add_equality takes scalar (degree-0) affine expressions; "
                             "use free multipliers for polynomial identities")
        con = EqualityConstraint(name or f"eq{len(self.equalities)}", expr, np.atleast_1d(float(rhs)))
        self.equalities.append(con)
        return con

    def maximize(self, expr) -> None:
        self._set_objective(expr, Sense.MAXIMIZE)

    def minimize(self, expr) -> None:
        self._set_objective(expr, Sense.MINIMIZE)

    def _set_objective(self, expr, sense):
        expr = self._as_linpoly(expr)
        if expr.degree > 0:
            raise ValueError("the objective must be a scalar affine expression in the decision variables")
        self.objective, self.sense = expr, sense

    def _as_linpoly(self, expr) -> LinPoly:
        if isinstance(expr, LinPoly):
            if expr.gens != self.gens:
                raise ValueError(f"expression over {expr.gens} used in a program over {self.gens}")
            return expr
        if isinstance(expr, Polynomial):
            return LinPoly.from_polynomial(expr, self.gens)
        return LinPoly.from_polynomial(as_polynomial(expr, self.gens), self.gens)

    # ------------------------------------------------------------------ complexity
    def n_lmivar(self) -> int:
        """Independent scalar LMI variables of the image (U + L(alpha)) form (SPEC §8).

        = number of decision variables + sum over SOS constraints of tau, where
        tau = (#Gram pairs) - (#distinct products) is the dimension of L(alpha).
        """
        return self.n_vars + sum(c.gram.n_pairs - c.gram.n_products for c in self.sos_constraints)

    def summary(self) -> str:
        lines = [f"SOSProgram over {len(self.gens)} variables, {self.n_vars} decision scalars"]
        for b in self.blocks:
            lines.append(f"  block {b.name}: {b.kind.value}, {b.size} scalars")
        for c in self.sos_constraints:
            lines.append(f"  SOS {c.name}: Gram blocks {' + '.join(f'{s}x{s}' for s in c.gram.sizes)}")
        lines.append(f"  N_LMIVAR = {self.n_lmivar()}")
        return "\n".join(lines)
