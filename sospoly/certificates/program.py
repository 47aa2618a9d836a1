"""SOS programs as pure data: *what* certificate is sought, not how it is solved.

An :class:`SOSProgram` owns a vector x of scalar decision variables, grouped in
named blocks:

* ``scalar(name)``: one free scalar;
* ``free_poly(degree)``: a polynomial with one free coefficient per monomial of
  degree <= ``degree`` (the multipliers r_k of the Positivstellensatz);
* ``sos_poly(degree)``: an SOS polynomial b_d(v)^T S b_d(v), S = S^T >= 0,
  parametrised by the upper-triangular entries of S (the multipliers s_k, q).

* ``psd_matrix(side)``: a symmetric PSD matrix (upper-triangular entries, svec pair order); the
  Gram matrix of a matrix SOS constraint (:mod:`sospoly.certificates.matrix_sos`).

Constraints: ``add_sos(u)`` -- the polynomial u, affine in x, is SOS, with its
Gram basis chosen from its degree; ``add_equality(expr, rhs)`` -- linear
equalities on x; ``add_identity(expr)`` -- a polynomial identity expr = 0 (every coefficient);
``add_inequality(expr)`` -- expr >= 0 for a scalar affine expr; ``add_soc(t, xs)`` --
||xs||_2 <= t; ``add_lmi(M)`` -- a symmetric matrix of scalar affine expressions is PSD;
``add_sos_matrix(M)`` -- a symmetric polynomial matrix is SOS (y^T M(v) y SOS in (v, y)).
An objective is a scalar affine expression, or (minimised) a convex / (maximised) a concave
quadratic :class:`~sospoly.algebra.quadexpr.QuadExpr` (lowered with an epigraph variable and a
rotated second-order cone).

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
from ..algebra.quadexpr import QuadExpr, convex_factor
from ..algebra.svec import triu_pairs

__all__ = ["square_entries",
           "SOSProgram", "Sense", "VarBlock", "SOSConstraint", "EqualityConstraint", "InequalityConstraint",
           "SOCConstraint", "LMIConstraint", "IdentityConstraint"]


class Sense(str, enum.Enum):
    """Objective sense of an :class:`SOSProgram`."""
    MINIMIZE = "minimize"
    MAXIMIZE = "maximize"
    FEASIBILITY = "feasibility"


class BlockKind(str, enum.Enum):
    SCALAR = "scalar"
    FREE_POLY = "free_poly"
    SOS_POLY = "sos_poly"   # Gram entries (upper triangle, svec pair order); PSD-constrained
    PSD_MATRIX = "psd_matrix"   # entries of a PSD matrix (upper triangle, svec pair order)


@dataclass(frozen=True)
class VarBlock:
    name: str
    kind: BlockKind
    start: int
    size: int
    monomials: np.ndarray | None = None       # FREE_POLY: exponents; SOS_POLY: Gram basis b
    gram: GramBasis | None = None             # SOS_POLY only
    side: int = 0                             # PSD_MATRIX only: the matrix side

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


@dataclass(frozen=True)
class InequalityConstraint:
    """``expr >= 0`` for a scalar affine expression (a nonnegative-orthant row)."""
    name: str
    expr: LinPoly


@dataclass(frozen=True)
class SOCConstraint:
    """``||(exprs[1], ..., exprs[k])||_2 <= exprs[0]`` (a second-order cone of dimension k + 1)."""
    name: str
    exprs: tuple


@dataclass(frozen=True)
class LMIConstraint:
    """A symmetric matrix of scalar affine expressions is PSD; ``entries`` in svec pair order
    (:func:`sospoly.algebra.svec.triu_pairs`)."""
    name: str
    side: int
    entries: tuple


@dataclass(frozen=True)
class IdentityConstraint:
    """The polynomial ``expr`` (affine in x) is identically zero: one equality per coefficient."""
    name: str
    expr: LinPoly


def square_entries(M, what: str) -> list:
    """Rows of a square list-of-lists (TypeError / ValueError naming ``what``)."""
    try:
        rows = [list(r) for r in M]
    except TypeError:
        raise TypeError(f"{what} must be a square list of lists") from None
    if not rows or any(len(r) != len(rows) for r in rows):
        raise ValueError(f"{what} must be a non-empty square list of lists, got row lengths {[len(r) for r in rows]}")
    return rows


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
        self.identities: list[IdentityConstraint] = []
        self.inequalities: list[InequalityConstraint] = []
        self.socs: list[SOCConstraint] = []
        self.lmis: list[LMIConstraint] = []
        self.objective: LinPoly | None = None
        self.objective_quadratic: QuadExpr | None = None   # the quadratic part when the objective is one
        self.sense: Sense = Sense.FEASIBILITY
        self.token = object()    # marks this program's decision variables (LinPoly.owner): others' are refused

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
        return LinPoly.variable_terms(self.gens, np.zeros((1, self.nvars_poly), np.int64), [blk.start], self.token)

    def scalars(self, k: int, name: str | None = None) -> list:
        """``k`` free scalars in one block (a list of scalar expressions)."""
        if int(k) != k or k < 1:
            raise ValueError(f"scalars count must be a positive integer, got {k!r}")
        blk = self._new_block(name, BlockKind.SCALAR, int(k))
        zero = np.zeros((1, self.nvars_poly), np.int64)
        return [LinPoly.variable_terms(self.gens, zero, [blk.start + t], self.token) for t in range(int(k))]

    def free_poly(self, degree: int, name: str | None = None, monomial_exponents=None) -> LinPoly:
        """A polynomial with free coefficients on all monomials of degree <= ``degree``."""
        if monomial_exponents is None:
            if degree < 0:
                raise ValueError(f"free polynomial degree must be >= 0, got {degree}")
            E = monomials(self.nvars_poly, int(degree))
        else:
            E = np.asarray(monomial_exponents, dtype=np.int64).reshape(-1, self.nvars_poly)
        blk = self._new_block(name, BlockKind.FREE_POLY, E.shape[0], monomials=E)
        return LinPoly.variable_terms(self.gens, E, np.arange(blk.start, blk.start + blk.size), self.token)

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
                       gb.pair_monomial, np.arange(blk.start, blk.start + npairs), w, owner=self.token)

    def psd_matrix(self, side: int, name: str | None = None) -> list:
        """A symmetric PSD matrix variable of the given side, as a list of lists of scalar expressions."""
        if int(side) != side or side < 1:
            raise ValueError(f"psd_matrix side must be a positive integer, got {side!r}")
        side = int(side)
        i, j = triu_pairs(side)
        blk = self._new_block(name, BlockKind.PSD_MATRIX, i.size, side=side)
        zero = np.zeros((1, self.nvars_poly), np.int64)
        M = [[None] * side for _ in range(side)]
        for t, (a, b) in enumerate(zip(i, j)):
            M[a][b] = M[b][a] = LinPoly.variable_terms(self.gens, zero, [blk.start + t], self.token)
        return M

    def gram_trace(self, block_name: str) -> LinPoly:
        """trace(S) of an SOS block, as a scalar expression."""
        blk = self.block(block_name)
        if blk.kind != BlockKind.SOS_POLY:
            raise ValueError(f"block {block_name!r} is not an SOS polynomial")
        diag = np.nonzero(blk.gram.pair_i == blk.gram.pair_j)[0]
        return LinPoly(self.gens, np.zeros((1, self.nvars_poly), np.int64), [0.0],
                       np.zeros(diag.size, np.int64), blk.start + diag, np.ones(diag.size), owner=self.token)

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

    def add_identity(self, expr, name: str | None = None) -> IdentityConstraint:
        """Require the polynomial ``expr`` (affine in the decision variables) to vanish identically."""
        con = IdentityConstraint(name or f"id{len(self.identities)}", self._as_linpoly(expr))
        self.identities.append(con)
        return con

    def _scalar(self, expr, what: str) -> LinPoly:
        if isinstance(expr, QuadExpr):
            raise TypeError(f"{what} must be affine in the decision variables, got a quadratic expression")
        e = self._as_linpoly_named(expr, what)
        if e.degree > 0:
            raise ValueError(f"{what} must be a scalar (degree-0) affine expression, got degree {e.degree} in "
                             f"{self.gens}; use add_sos for polynomial nonnegativity")
        return e

    def add_inequality(self, expr, name: str | None = None) -> InequalityConstraint:
        """Require ``expr >= 0`` for a scalar affine expression of the decision variables."""
        con = InequalityConstraint(name or f"ineq{len(self.inequalities)}", self._scalar(expr, "add_inequality expr"))
        self.inequalities.append(con)
        return con

    def add_soc(self, t, xs, name: str | None = None) -> SOCConstraint:
        """Require ``||xs||_2 <= t`` (t and every entry of xs scalar affine expressions)."""
        if isinstance(xs, (str, bytes)) or not hasattr(xs, "__iter__"):
            raise TypeError(f"add_soc xs must be a sequence of scalar expressions, got {type(xs).__name__}")
        xs = list(xs)
        if not xs:
            raise ValueError("add_soc xs must be a non-empty sequence of scalar expressions")
        exprs = (self._scalar(t, "add_soc t"),) + tuple(self._scalar(e, "add_soc xs entry") for e in xs)
        con = SOCConstraint(name or f"soc{len(self.socs)}", exprs)
        self.socs.append(con)
        return con

    def add_lmi(self, M, name: str | None = None) -> LMIConstraint:
        """Require the symmetric matrix ``M`` (list of lists of scalar affine expressions) to be PSD."""
        rows = square_entries(M, "add_lmi M")
        side = len(rows)
        ent = [[self._scalar(v, f"add_lmi M[{a}][{b}]") for b, v in enumerate(r)] for a, r in enumerate(rows)]
        i, j = triu_pairs(side)
        for a, b in zip(i, j):
            if a != b and not _same_affine(ent[a][b], ent[b][a], self.n_vars):
                raise ValueError(f"add_lmi M must be symmetric: M[{a}][{b}] != M[{b}][{a}]")
        con = LMIConstraint(name or f"lmi{len(self.lmis)}", side, tuple(ent[a][b] for a, b in zip(i, j)))
        self.lmis.append(con)
        return con

    def add_sos_matrix(self, M, degree: int | None = None, name: str | None = None, basis=None):
        """Require the symmetric polynomial matrix ``M`` to be SOS: M(v) = (I (x) b(v))^T G (I (x) b(v)) with
        G PSD (see :mod:`sospoly.certificates.matrix_sos`).  Returns the
        :class:`~sospoly.certificates.matrix_sos.MatrixSOSConstraint`."""
        from .matrix_sos import add_sos_matrix

        return add_sos_matrix(self, M, degree=degree, name=name, basis=basis)

    def add_dsos(self, expr, degree: int | None = None, name: str | None = None, basis=None):
        """Require ``expr`` to be DSOS: b^T Q b with Q diagonally dominant (an LP; Ahmadi-Majumdar 2019).
        See :mod:`sospoly.certificates.dd`."""
        from .dd import DDKind, add_dd

        return add_dd(self, expr, DDKind.DSOS, degree=degree, name=name, basis=basis)

    def add_sdsos(self, expr, degree: int | None = None, name: str | None = None, basis=None):
        """Require ``expr`` to be SDSOS: b^T Q b with Q scaled diagonally dominant (a sum of 2x2 PSD
        blocks: second-order cones).  See :mod:`sospoly.certificates.dd`."""
        from .dd import DDKind, add_dd

        return add_dd(self, expr, DDKind.SDSOS, degree=degree, name=name, basis=basis)

    def maximize(self, expr) -> None:
        self._set_objective(expr, Sense.MAXIMIZE)

    def minimize(self, expr) -> None:
        self._set_objective(expr, Sense.MINIMIZE)

    def _set_objective(self, expr, sense):
        quad = None
        if isinstance(expr, QuadExpr):
            quad, expr = expr, expr.affine
        expr = self._as_linpoly_named(expr, "the objective")
        if expr.degree > 0:
            raise ValueError("the objective must be a scalar affine or quadratic expression in the decision "
                             "variables")
        if quad is not None:
            self._own(None, np.concatenate([quad.qi, quad.qj]))
            _check_curvature(quad, self.n_vars, sense, self.blocks)
        self.objective, self.sense, self.objective_quadratic = expr, sense, quad

    def _as_linpoly_named(self, expr, what: str) -> LinPoly:
        """:meth:`_as_linpoly`, its TypeError / ValueError prefixed with ``what`` (the argument's name)."""
        try:
            return self._as_linpoly(expr)
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"{what}: {exc}") from None

    def _as_linpoly(self, expr) -> LinPoly:
        if isinstance(expr, LinPoly):
            if expr.gens != self.gens:
                raise ValueError(f"expression over {expr.gens} used in a program over {self.gens}")
            self._own(expr.owner, expr.cols)
            return expr
        if isinstance(expr, Polynomial):
            return LinPoly.from_polynomial(expr, self.gens)
        return LinPoly.from_polynomial(as_polynomial(expr, self.gens), self.gens)

    def _own(self, owner, cols) -> None:
        """ValueError for decision variables of another program (review 26a F9: they would alias this program's
        columns): an expression owned by another program, or columns beyond this program's variables."""
        if owner is not None and owner is not self.token:
            raise ValueError("the expression uses decision variables of another SOSProgram; create them with this "
                             "program's scalar / free_poly / sos_poly / psd_matrix")
        if cols.size and int(cols.max()) >= self.n_vars:
            raise ValueError(f"the expression uses decision variable {int(cols.max())}, but this SOSProgram has "
                             f"{self.n_vars}: variables of another program?")

    def objective_value(self, x) -> float:
        """The objective (affine + quadratic part) at decision values ``x``."""
        val = float(self.objective.value(x).coefficient((0,) * self.nvars_poly)) if self.objective is not None else 0.0
        if self.objective_quadratic is not None:
            val = self.objective_quadratic.value(x)
        return val

    # ------------------------------------------------------------------ complexity
    def n_lmivar(self) -> int:
        """Independent scalar LMI variables of the image (U + L(alpha)) form (SPEC §8).

        = number of decision variables + sum over SOS constraints of tau, where
        tau = (#Gram pairs) - (#distinct products) is the dimension of L(alpha); plus the epigraph scalar of a
        quadratic objective.
        """
        epigraph = 1 if self.objective_quadratic is not None and self.sense != Sense.FEASIBILITY else 0
        return self.n_vars + epigraph + sum(c.gram.n_pairs - c.gram.n_products for c in self.sos_constraints)

    @property
    def has_conic_extras(self) -> bool:
        """Does the program use cones beyond zero and PSD (inequalities, second-order cones, a quadratic
        objective)?  Those the batched interior-point method does not handle; Clarabel and cvxpy do."""
        return bool(self.inequalities or self.socs or self.objective_quadratic is not None)

    def summary(self) -> str:
        lines = [f"SOSProgram over {len(self.gens)} variables, {self.n_vars} decision scalars"]
        for b in self.blocks:
            lines.append(f"  block {b.name}: {b.kind.value}, {b.size} scalars")
        for c in self.sos_constraints:
            lines.append(f"  SOS {c.name}: Gram blocks {' + '.join(f'{s}x{s}' for s in c.gram.sizes)}")
        lines.append(f"  N_LMIVAR = {self.n_lmivar()}")
        return "\n".join(lines)


def _same_affine(a: LinPoly, b: LinPoly, n_vars: int) -> bool:
    """Do two scalar affine expressions coincide to round-off, coefficient by coefficient (each decision
    variable's coefficients, and the constants, against their own size: review 26a F9, where a difference 0.5 t
    hid under a tolerance set by entries ~1e12 of other variables)?"""
    la, lb = (np.asarray(e.linear_matrix(n_vars).sum(axis=0)).ravel() for e in (a, b))
    ca, cb = float(a.const.sum()), float(b.const.sum())
    lin_ok = np.all(np.abs(la - lb) <= 1e-12 * np.maximum(np.abs(la), np.abs(lb)))
    return bool(lin_ok) and abs(ca - cb) <= 1e-12 * max(abs(ca), abs(cb))


def _check_curvature(quad: QuadExpr, n_vars: int, sense: Sense, blocks=()) -> None:
    """A minimised quadratic must be convex, a maximised one concave: +-P PSD at each direction's own scale
    (:func:`~sospoly.algebra.quadexpr.convex_factor`); ValueError naming a direction of the wrong curvature."""
    sign = 1.0 if sense == Sense.MINIMIZE else -1.0
    P = quad.matrix(n_vars) * sign
    if not P.size:
        return
    F, v, rel = convex_factor(P)
    if F is None:
        what = "convex" if sense == Sense.MINIMIZE else "concave"
        top = np.argsort(-np.abs(v))[:3]
        names = ", ".join(f"{_var_name(blocks, int(k))}: {v[k]:.3g}" for k in top if v[k] != 0)
        raise ValueError(f"the quadratic objective must be {what} to be {sense.value}d: along the direction "
                         f"({names}) its curvature is {sign * float(v @ P @ v):.3g}, {rel:.3g} times that "
                         f"direction's own diagonal terms (nonconvex objectives are not solved)")


def _var_name(blocks, k: int) -> str:
    """The decision variable of global index ``k`` as 'block' or 'block[i]'."""
    for b in blocks:
        if b.start <= k < b.start + b.size:
            return b.name if b.size == 1 else f"{b.name}[{k - b.start}]"
    return f"x[{k}]"
