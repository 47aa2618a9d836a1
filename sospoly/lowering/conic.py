"""Lowering of an :class:`~sospoly.certificates.program.SOSProgram` to one conic standard form.

Standard form (Clarabel's, with P = 0)::

    minimise    q^T x
    subject to  A x + s = b,   s in K = {0}^z  x  R_+^l  x  Q^{m_1} x ... x  Q^{m_r}
                                        x  S_+^{s_1}  x ... x  S_+^{s_k}

with Q^m = {(t, y) in R x R^{m-1} : ||y||_2 <= t} the second-order cone.  PSD blocks are in
the svec convention of :mod:`sospoly.algebra.svec`.  Rows are ordered: all zero-cone rows first
(linear equalities, polynomial identities, coefficient matching), then the nonnegative rows of
scalar inequalities, the second-order cones (user cones, then the epigraph cone of a quadratic
objective), then one PSD block per SOS-polynomial multiplier and PSD matrix variable, one per
SOS constraint (per Gram block) and one per LMI.

A convex quadratic objective x^T P x + l^T x (P = F^T F) is minimised as l^T x + t over one extra
last column t with the rotated cone x^T P x <= t written as a second-order cone:
||(t - 1, 2 F x)||_2 <= t + 1.

Two Gram forms (SPEC §4):

``GramForm.IMAGE`` (default, the paper's)
    u is SOS iff U(x) + L(alpha) >= 0: the Gram matrix is an *affine image* of the
    decision variables.  U puts every coefficient u_m on one canonical pair (i, j)
    with b_i b_j = m (the diagonal pair when m is a square); every other pair
    (i', j') of m gets a new free alpha with +alpha on (i', j') and -alpha on the
    canonical pair, which spans L = {L = L^T : b^T L b = 0} with exactly
    tau = #pairs - #monomials elements.  No equality rows are needed, and the
    number of columns is N_LMIVAR.
``GramForm.KERNEL``
    coefficient matching: a free Gram variable Q >= 0 and one linear equality per
    monomial, sum_{b_i b_j = m} Q_ij = u_m(x).

Both forms describe the same feasible set; tests check they give the same bounds.
A program may carry *parameters* (``param_terms`` of SOS constraints): the
lowered data is then ``A + sum_k theta_k A_k``, ``b + sum_k theta_k b_k`` so a
re-solve with new parameter values needs no re-assembly (compile once).

This module only lowers: a solver consumes the lowered problem
(:func:`sospoly.solve_conic_problem`, :mod:`sospoly.solvers`); nothing here imports a solver.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..algebra.basis import GramBlocks, MonomialIndex
from ..algebra.linpoly import LinPoly
from ..algebra.quadexpr import convex_factor
from ..certificates.program import BlockKind, Sense, SOSProgram
from ..algebra.svec import smat, svec_scale
from ..budget import check_deadline

__all__ = ["GramForm", "Cone", "CONE_KINDS", "ConicProblem", "lower", "gram_structure"]


class GramForm(str, enum.Enum):
    """How an SOS constraint is lowered: ``image`` (U + L(alpha), the paper's) or ``kernel`` (coefficient matching)."""
    IMAGE = "image"
    KERNEL = "kernel"


#: the cone kinds of the standard form (module docstring)
CONE_KINDS = ("zero", "nonneg", "soc", "psd")


@dataclass(frozen=True)
class Cone:
    kind: str      # one of CONE_KINDS: "zero", "nonneg", "soc" or "psd"
    dim: int       # number of rows
    size: int = 0  # matrix side for "psd"

    def __post_init__(self):
        if self.kind not in CONE_KINDS:
            raise ValueError(f"Cone kind must be one of {CONE_KINDS}, got {self.kind!r}")


@dataclass(frozen=True)
class PSDBlockMap:
    """Where a Gram matrix lives in the lowered problem."""
    name: str
    row_start: int
    size: int                  # matrix side
    source: str                # "constraint", "multiplier", "matrix" (a PSD matrix variable) or "lmi"
    var_start: int | None = None   # kernel form: first column of its Q variables
    basis: np.ndarray | None = field(default=None, compare=False, repr=False)   # exponents of b(v) (SOS blocks)


@dataclass(frozen=True)
class ConicProblem:
    """Conic data in the standard form of the module docstring (min q^T x, A x + s = b, s in the cones),
    with the PSD block map and the affine parameter matrices."""
    q: np.ndarray
    A: sp.csc_matrix
    b: np.ndarray
    cones: tuple
    n_program_vars: int
    psd_blocks: tuple
    objective_sign: float = 1.0       # user objective = objective_sign * q^T x + objective_offset
    objective_offset: float = 0.0
    form: GramForm = GramForm.IMAGE
    params: dict = field(default_factory=dict)   # name -> (A_k, b_k)

    @property
    def n_cols(self) -> int:
        return self.A.shape[1]

    @property
    def n_rows(self) -> int:
        return self.A.shape[0]

    def instantiate(self, **theta: float) -> ConicProblem:
        """The problem with numeric parameter values (parameters not given are 0)."""
        unknown = set(theta) - set(self.params)
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}; this problem has {sorted(self.params)}")
        A, b = self.A, self.b
        for name, (Ak, bk) in self.params.items():
            t = float(theta.get(name, 0.0))
            if t != 0.0:
                A = A + t * Ak
                b = b + t * bk
        return ConicProblem(self.q, sp.csc_matrix(A), b, self.cones, self.n_program_vars, self.psd_blocks,
                            self.objective_sign, self.objective_offset, self.form, {})

    def with_margin(self, block: str, cap: float = 1.0) -> ConicProblem:
        """Feasibility with a margin: a last column t, G_block - t I in the PSD cone, t <= cap,
        minimise -t.  The augmented problem is strictly feasible for every parameter value, so
        interior-point solvers stay well-posed at the boundary of the original feasible set
        (where the plain feasibility problem fails numerically); the original problem is
        feasible iff t* >= 0.  ``gram_matrices(x[:-1])`` of the original gives the certificate."""
        blk = next(b for b in self.psd_blocks if b.name == block)
        s = blk.size
        rows = blk.row_start + np.cumsum(np.arange(1, s + 1)) - 1   # svec diagonal positions
        col = sp.csc_matrix((np.ones(s), (rows, np.zeros(s, np.int64))), shape=(self.n_rows, 1))
        cap_row = sp.csc_matrix(([1.0], ([0], [self.n_cols])), shape=(1, self.n_cols + 1))
        A = sp.vstack([sp.hstack([self.A, col]), cap_row]).tocsc()
        b = np.append(self.b, cap)
        q = np.zeros(self.n_cols + 1)
        q[-1] = -1.0
        return ConicProblem(q, A, b, self.cones + (Cone("nonneg", 1),), self.n_program_vars, self.psd_blocks,
                            -1.0, 0.0, self.form, {})

    # ------------------------------------------------------------------ files
    def to_sdpa(self, path):
        """Write the problem as an SDPA sparse file (``.dat-s``; :mod:`sospoly.io.sdpa`)."""
        from ..io.sdpa import write_sdpa

        return write_sdpa(self, path)

    @classmethod
    def from_sdpa(cls, path) -> ConicProblem:
        """Read an SDPA sparse file (:mod:`sospoly.io.sdpa`)."""
        from ..io.sdpa import read_sdpa

        return read_sdpa(path)

    def to_cbf(self, path):
        """Write the problem in the Conic Benchmark Format (``.cbf``; :mod:`sospoly.io.cbf`)."""
        from ..io.cbf import write_cbf

        return write_cbf(self, path)

    @classmethod
    def from_cbf(cls, path) -> ConicProblem:
        """Read a CBF file of the subset :func:`sospoly.io.cbf.write_cbf` writes (:mod:`sospoly.io.cbf`)."""
        from ..io.cbf import read_cbf

        return read_cbf(path)

    def slack(self, x: np.ndarray) -> np.ndarray:
        """s = b - A x (exact, recomputed from x)."""
        return self.b - self.A @ x

    def gram_matrices(self, x: np.ndarray) -> dict:
        """Gram matrices of every PSD block recomputed from the primal x."""
        out = {}
        for blk in self.psd_blocks:
            if self.form == GramForm.KERNEL and blk.var_start is not None:
                n = blk.size * (blk.size + 1) // 2
                out[blk.name] = smat(svec_scale(blk.size) * x[blk.var_start:blk.var_start + n])
            else:
                rows = slice(blk.row_start, blk.row_start + blk.size * (blk.size + 1) // 2)
                out[blk.name] = smat(self.b[rows] - self.A[rows] @ x)
        return out

    def dual_matrices(self, z: np.ndarray) -> dict:
        return {blk.name: smat(z[blk.row_start:blk.row_start + blk.size * (blk.size + 1) // 2])
                for blk in self.psd_blocks}


@dataclass(frozen=True)
class GramStructure:
    """Canonical pair per monomial and the alpha pairs of the image form (pairs are indexed over the
    concatenated blocks of a :class:`~sospoly.algebra.basis.GramBlocks`, i.e. by svec row)."""
    canonical: np.ndarray   # (n_products,) pair index of the canonical pair
    alpha_pairs: np.ndarray  # (tau,) pair index carrying each alpha
    alpha_canonical: np.ndarray  # (tau,) canonical pair of the same monomial
    kappa: np.ndarray        # (n_pairs,) svec entry per unit monomial contribution (1 / svec scale)


def gram_structure(gb) -> GramStructure:
    """The explicit L(alpha) basis of SPEC §4 for Gram blocks or one GramBasis (see module docstring): every monomial's
    coefficient goes on one canonical pair (a diagonal pair if there is one, the first otherwise);
    every other pair of the same monomial carries one alpha."""
    if not isinstance(gb, GramBlocks):
        gb = GramBlocks.of(gb)
    pm = gb.pair_monomial
    is_diag = gb.pair_diag
    order = np.lexsort((np.arange(pm.size), ~is_diag, pm))
    first = np.ones(order.size, dtype=bool)
    first[1:] = pm[order][1:] != pm[order][:-1]
    canonical = np.empty(gb.n_products, dtype=np.int64)
    canonical[pm[order][first]] = order[first]
    alpha_pairs = np.sort(order[~first])
    kappa = 1.0 / np.concatenate([svec_scale(b.size) for b in gb.blocks])
    return GramStructure(canonical, alpha_pairs, canonical[pm[alpha_pairs]], kappa)


class _Builder:
    def __init__(self):
        self.r, self.c, self.v = [], [], []

    def add(self, rows, cols, vals):
        self.r.append(np.asarray(rows, np.int64))
        self.c.append(np.asarray(cols, np.int64))
        self.v.append(np.asarray(vals, float))

    def matrix(self, nrows, ncols):
        if not self.r:
            return sp.csc_matrix((nrows, ncols))
        return sp.csc_matrix((np.concatenate(self.v), (np.concatenate(self.r), np.concatenate(self.c))),
                             shape=(nrows, ncols))


class _Assembly:
    """Rows s = b - A x under construction: the main (A, b) and one (A_k, b_k) per parameter."""

    def __init__(self, param_names):
        self.main, self.b = _Builder(), []
        self.params = {k: (_Builder(), []) for k in param_names}

    def target(self, name):
        return (self.main, self.b) if name is None else self.params[name]

    def add_affine(self, name, expr: LinPoly, rows_of_terms: np.ndarray, sign: float, scale=None) -> None:
        """Rows ``rows_of_terms[t]`` (-1: skip) receive ``sign * scale[t] * term t of expr``:
        b += sign * scale * const, A -= sign * scale * linear part."""
        builder, bent = self.target(name)
        scale = np.ones(expr.E.shape[0]) if scale is None else scale
        keep = rows_of_terms >= 0
        if np.any(keep):
            bent.append((rows_of_terms[keep], sign * scale[keep] * expr.const[keep]))
        if expr.rows.size:
            rr = rows_of_terms[expr.rows]
            k2 = rr >= 0
            builder.add(rr[k2], expr.cols[k2], -sign * scale[expr.rows][k2] * expr.vals[k2])

    @staticmethod
    def _vector(entries, nrows):
        b = np.zeros(nrows)
        for r_, v_ in entries:
            np.add.at(b, r_, v_)
        return b

    def finish(self, nrows, ncols):
        A = self.main.matrix(nrows, ncols)
        b = self._vector(self.b, nrows)
        params = {k: (bld.matrix(nrows, ncols), self._vector(ent, nrows)) for k, (bld, ent) in self.params.items()}
        return A, b, params


def _terms(con):
    """(parameter name or None, expression) of an SOS constraint's data."""
    return [(None, con.expr)] + list(con.param_terms.items())


def lower(program: SOSProgram, form: GramForm = GramForm.IMAGE) -> ConicProblem:
    """Assemble the conic data of ``program`` (see module docstring): columns, then the rows of the zero,
    nonnegative and second-order, and PSD cones in that order, then the objective."""
    form = GramForm(form)
    param_names = sorted({k for con in program.sos_constraints for k in con.param_terms})
    epi = _epigraph_factor(program)
    extra_start, t_col, ncols = _columns(program, form, epi)
    asm = _Assembly(param_names)
    n_zero = _zero_rows(program, form, asm, extra_start)
    cones = [Cone("zero", n_zero)] if n_zero else []
    row = _scalar_cone_rows(program, asm, n_zero, cones, epi, t_col)
    psd_blocks = []
    row = _variable_psd_rows(program, asm, row, cones, psd_blocks)
    row = _sos_psd_rows(program, form, asm, row, cones, psd_blocks, extra_start)
    row = _lmi_rows(program, asm, row, cones, psd_blocks)
    A, b, params = asm.finish(row, ncols)
    q, sign, offset = _objective(program, ncols, t_col)
    return ConicProblem(q, A, b, tuple(cones), program.n_vars, tuple(psd_blocks), sign, offset, form, params)


def _columns(program: SOSProgram, form: GramForm, epi) -> tuple[list, int | None, int]:
    """Columns: the program's variables, then per SOS constraint its extra variables (the tau alphas of the
    image form, or the n_pairs Gram entries Q of the kernel form), then the epigraph t of a quadratic
    objective.  Returns (first extra column per constraint, t's column or None, number of columns)."""
    col = program.n_vars
    extra_start = []
    for con in program.sos_constraints:
        extra_start.append(col)
        col += con.gram.n_pairs - (con.gram.n_products if form == GramForm.IMAGE else 0)
    t_col = col if epi is not None else None
    return extra_start, t_col, col + (1 if epi is not None else 0)


def _zero_rows(program: SOSProgram, form: GramForm, asm: _Assembly, extra_start: list) -> int:
    """The zero-cone rows: linear equalities (s = rhs - expr), polynomial identities (every coefficient),
    the monomials of SOS expressions outside the Gram products (u_m = 0) and, in the kernel form, the
    coefficient matching u_m - sum_{b_i b_j = m} w_ij Q_ij = 0.  Returns their number."""
    row = 0
    for eq in program.equalities:          # linear equalities: s = rhs - expr = 0
        asm.add_affine(None, eq.expr, np.full(eq.expr.E.shape[0], row, dtype=np.int64), -1.0)
        asm.b.append((np.array([row]), eq.rhs))
        row += 1
    for ident in program.identities:       # polynomial identities: every coefficient = 0
        asm.add_affine(None, ident.expr, row + np.arange(ident.expr.E.shape[0]), -1.0)
        row += ident.expr.E.shape[0]
    for con in program.sos_constraints:    # monomials of SOS expressions outside the Gram products: u_m = 0
        row = _missing_monomial_rows(program, con, asm, row)
    if form == GramForm.KERNEL:            # coefficient matching rows  u_m - sum w Q = 0
        for k, con in enumerate(program.sos_constraints):
            gb = con.gram
            w = np.where(gb.pair_diag, 1.0, 2.0)
            asm.main.add(row + gb.pair_monomial, extra_start[k] + np.arange(gb.n_pairs), w)
            for name, expr in _terms(con):
                idx = gb.product_index.find(expr.E, missing_ok=True)
                asm.add_affine(name, expr, np.where(idx >= 0, idx + row, -1), 1.0)
            row += gb.n_products
    return row


def _missing_monomial_rows(program: SOSProgram, con, asm: _Assembly, row: int) -> int:
    """u_m = 0 for every monomial m of an SOS constraint's data that no Gram product b_i b_j gives."""
    check_deadline("lowering the program")
    missing = {}
    for _, expr in _terms(con):
        idx = con.gram.product_index.find(expr.E, missing_ok=True)
        for e in map(tuple, expr.E[idx < 0]):
            missing.setdefault(e, None)
    if not missing:
        return row
    mindex = MonomialIndex(np.array(list(missing), dtype=np.int64).reshape(-1, len(program.gens)))
    for name, expr in _terms(con):
        ridx = mindex.find(expr.E, missing_ok=True)
        asm.add_affine(name, expr, np.where(ridx >= 0, ridx + row, -1), -1.0)
    return row + len(mindex)


def _variable_psd_rows(program: SOSProgram, asm: _Assembly, row: int, cones: list, psd_blocks: list) -> int:
    """One PSD block per SOS-polynomial multiplier and PSD matrix variable: s = svec(G) of its columns."""
    for blk in program.blocks:
        if blk.kind not in (BlockKind.SOS_POLY, BlockKind.PSD_MATRIX):
            continue
        s, n = (blk.gram.size if blk.kind == BlockKind.SOS_POLY else blk.side), blk.size
        asm.main.add(row + np.arange(n), blk.start + np.arange(n), -svec_scale(s))
        psd_blocks.append(PSDBlockMap(blk.name, row, s, "multiplier" if blk.kind == BlockKind.SOS_POLY else "matrix",
                                      basis=blk.gram.b if blk.kind == BlockKind.SOS_POLY else None))
        cones.append(Cone("psd", n, s))
        row += n
    return row


def _sos_psd_rows(program: SOSProgram, form: GramForm, asm: _Assembly, row: int, cones: list, psd_blocks: list,
                  extra_start: list) -> int:
    """One PSD block per Gram block of every SOS constraint: in the image form s = svec(U(x) + L(alpha))
    (each coefficient on its canonical pair, +alpha / -alpha on the other pairs of its monomial); in the
    kernel form s = svec(Q) of the constraint's Q columns."""
    for k, con in enumerate(program.sos_constraints):
        check_deadline("lowering the program")
        gb = con.gram
        if form == GramForm.IMAGE:
            st = gram_structure(gb)
            for name, expr in _terms(con):
                idx = gb.product_index.find(expr.E, missing_ok=True)
                pair_row = np.where(idx >= 0, st.canonical[np.maximum(idx, 0)], -1)
                scale = np.where(idx >= 0, st.kappa[np.maximum(pair_row, 0)], 0.0)
                asm.add_affine(name, expr, np.where(idx >= 0, row + pair_row, -1), 1.0, scale)
            acols = extra_start[k] + np.arange(st.alpha_pairs.size)
            asm.main.add(row + st.alpha_pairs, acols, -st.kappa[st.alpha_pairs])
            asm.main.add(row + st.alpha_canonical, acols, st.kappa[st.alpha_canonical])
        else:
            scale = np.concatenate([svec_scale(b.size) for b in gb.blocks])
            asm.main.add(row + np.arange(gb.n_pairs), extra_start[k] + np.arange(gb.n_pairs), -scale)
        for j, (bname, blk_basis) in enumerate(zip(con.block_names(), gb.blocks)):
            off = int(gb.block_offsets[j])
            var_start = None if form == GramForm.IMAGE else extra_start[k] + off
            psd_blocks.append(PSDBlockMap(bname, row + off, blk_basis.size, "constraint", var_start, blk_basis.b))
            cones.append(Cone("psd", blk_basis.n_pairs, blk_basis.size))
        row += gb.n_pairs
    return row


def _lmi_rows(program: SOSProgram, asm: _Assembly, row: int, cones: list, psd_blocks: list) -> int:
    """One PSD block per LMI: s = svec(M(x))."""
    for lmi in program.lmis:
        scale = svec_scale(lmi.side)
        for t, expr in enumerate(lmi.entries):
            asm.add_affine(None, expr, np.full(expr.E.shape[0], row + t, np.int64), float(scale[t]))
        psd_blocks.append(PSDBlockMap(lmi.name, row, lmi.side, "lmi"))
        cones.append(Cone("psd", len(lmi.entries), lmi.side))
        row += len(lmi.entries)
    return row


def _objective(program: SOSProgram, ncols: int, t_col: int | None) -> tuple[np.ndarray, float, float]:
    """(q, objective_sign, objective_offset): the user objective is objective_sign * q^T x + objective_offset
    (a maximisation is minimised as -q; the epigraph t of a quadratic objective has cost 1)."""
    n0 = program.n_vars
    q = np.zeros(ncols)
    sign, offset = 1.0, 0.0
    if program.objective is not None and program.sense != Sense.FEASIBILITY:
        obj = program.objective
        lin = np.zeros(n0)
        np.add.at(lin, obj.cols, obj.vals)
        offset = float(obj.const.sum())
        if program.sense == Sense.MAXIMIZE:
            q[:n0] = -lin
            sign = -1.0
        else:
            q[:n0] = lin
        if t_col is not None:
            q[t_col] = 1.0
    return q, sign, offset


def _epigraph_factor(program: SOSProgram) -> np.ndarray | None:
    """F with F^T F = +-P of a quadratic objective (sign: + minimised, - maximised; the Jacobi-scaled factor of
    :func:`~sospoly.algebra.quadexpr.convex_factor`), or None."""
    quad = program.objective_quadratic
    if quad is None or program.sense == Sense.FEASIBILITY:
        return None
    P = quad.matrix(program.n_vars) * (1.0 if program.sense == Sense.MINIMIZE else -1.0)
    F, v, rel = convex_factor(P)
    if F is None:       # (SOSProgram refuses such an objective; a program built around it is refused here too)
        raise ValueError(f"the quadratic objective is not {'convex' if program.sense == Sense.MINIMIZE else 'concave'}"
                         f" (relative curvature {rel:.3g} along a direction): refusing to drop its negative part")
    return F


def _scalar_cone_rows(program: SOSProgram, asm: _Assembly, row: int, cones: list, epi, t_col) -> int:
    """Rows of scalar inequalities (s = expr >= 0), second-order cones (s = (t, xs)) and the epigraph
    cone ||(t - 1, 2 F x)|| <= t + 1 of a quadratic objective; returns the next free row."""
    for ineq in program.inequalities:
        asm.add_affine(None, ineq.expr, np.full(ineq.expr.E.shape[0], row, np.int64), 1.0)
        row += 1
    if program.inequalities:
        cones.append(Cone("nonneg", len(program.inequalities)))
    for soc in program.socs:
        for t, expr in enumerate(soc.exprs):
            asm.add_affine(None, expr, np.full(expr.E.shape[0], row + t, np.int64), 1.0)
        cones.append(Cone("soc", len(soc.exprs)))
        row += len(soc.exprs)
    if epi is not None:
        k, n0 = epi.shape
        asm.main.add([row, row + 1], [t_col, t_col], [-1.0, -1.0])
        asm.b.append((np.array([row, row + 1]), np.array([1.0, -1.0])))
        r, c = np.nonzero(epi)
        asm.main.add(row + 2 + r, c, -2.0 * epi[r, c])
        cones.append(Cone("soc", k + 2))
        row += k + 2
    return row
