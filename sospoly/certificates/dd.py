"""DSOS and SDSOS constraints: inner approximations of the SOS cone by LP and SOCP
(Ahmadi & Majumdar, "DSOS and SDSOS optimization", SIAM J. Appl. Algebra Geom. 2019;
SumOfSquares.jl's ``DSOSCone`` / ``SDSOSCone``).

p is DSOS when p = b^T Q b with Q *diagonally dominant* (Q_ii >= sum_{j != i} |Q_ij|), and SDSOS
when Q is *scaled* diagonally dominant, i.e. a sum of PSD matrices each supported on one 2 x 2
principal submatrix.  DSOS subset SDSOS subset SOS, so the bounds they give are valid and never
better than the SOS bound.

Lowering (all on :class:`~sospoly.certificates.program.SOSProgram` primitives, no new cone):
Q's upper-triangular entries are free scalars and ``p - b^T Q b = 0`` a polynomial identity; then

* DSOS: t_ij >= |Q_ij| (two inequalities per off-diagonal pair) and Q_ii - sum_j t_ij >= 0;
* SDSOS: per pair (i, j) a 2 x 2 block [[a_ij, Q_ij], [Q_ij, c_ij]] PSD, written as the second-order
  cone ||(2 Q_ij, a_ij - c_ij)||_2 <= a_ij + c_ij, and Q_ii - sum of the blocks' diagonal entries on i
  >= 0 (the remainder is a nonnegative diagonal, itself SDD).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from ..algebra.basis import even_degree, exponent_rows, monomials
from ..algebra.linpoly import LinPoly
from ..algebra.svec import smat, svec_scale, triu_pairs

__all__ = ["DDKind", "DDConstraint", "add_dd"]


class DDKind(str, enum.Enum):
    """Which inner approximation of the SOS cone."""
    DSOS = "dsos"
    SDSOS = "sdsos"


@dataclass(frozen=True)
class DDConstraint:
    """A DSOS / SDSOS constraint: the block of Q's entries and the monomial basis b."""
    name: str
    kind: DDKind
    basis: np.ndarray
    q_block: str

    def gram(self, program, solution) -> np.ndarray:
        """Q at the solution (symmetric, side |b|)."""
        v = solution.block_values(program, self.q_block)
        return smat(v * svec_scale(self.basis.shape[0]))


def _basis(program, expr: LinPoly, degree, basis) -> np.ndarray:
    if basis is not None:
        return exponent_rows(basis, program.nvars_poly, "basis")
    deg = max(expr.degree, 0)
    degree = deg + deg % 2 if degree is None else even_degree(degree, deg, "a DSOS/SDSOS constraint's degree")
    return monomials(program.nvars_poly, degree // 2)


def add_dd(program, expr, kind: DDKind, degree: int | None = None, name: str | None = None,
           basis=None) -> DDConstraint:
    """Require ``expr`` to be DSOS or SDSOS (module docstring)."""
    kind = DDKind(kind)
    expr = program._as_linpoly_named(expr, f"add_{kind.value} expr")
    b = _basis(program, expr, degree, basis)
    s = b.shape[0]
    i, j = triu_pairs(s)
    name = name or f"{kind.value}{len(program.blocks)}"
    Q = program.scalars(i.size, name=f"{name}.Q")
    start = program.block(f"{name}.Q").start
    w = np.where(i == j, 1.0, 2.0)
    gram = LinPoly(program.gens, b[i] + b[j], np.zeros(i.size), np.arange(i.size), start + np.arange(i.size), w)
    program.add_identity(expr - gram, name=f"{name}.identity")
    off = np.nonzero(i != j)[0]
    diag_pos = {int(a): int(t) for t, (a, c) in enumerate(zip(i, j)) if a == c}
    load = {a: [] for a in range(s)}                 # per diagonal index: what the off-diagonal pairs take
    if off.size and kind == DDKind.DSOS:
        T = program.scalars(off.size, name=f"{name}.T")
        for t, p in enumerate(off):
            program.add_inequality(T[t] - Q[p])
            program.add_inequality(T[t] + Q[p])
            load[int(i[p])].append(T[t])
            load[int(j[p])].append(T[t])
    elif off.size:
        a = program.scalars(off.size, name=f"{name}.a")
        c = program.scalars(off.size, name=f"{name}.c")
        for t, p in enumerate(off):
            program.add_soc(a[t] + c[t], [2.0 * Q[p], a[t] - c[t]])
            load[int(i[p])].append(a[t])
            load[int(j[p])].append(c[t])
    for k in range(s):
        rest = Q[diag_pos[k]]
        for e in load[k]:
            rest = rest - e
        program.add_inequality(rest)
    return DDConstraint(name, kind, b, f"{name}.Q")
