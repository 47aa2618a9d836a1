"""Polynomials whose coefficients are affine in the decision variables of a program.

``LinPoly`` stores, over fixed generators, the exponent rows ``E`` (m x n), a
constant coefficient per row and a sparse linear part in COO triplets
``(row, var, val)`` referring to the program's global decision-variable index.
It supports + and - with LinPolys, Polynomials and numbers, and multiplication
by a *numeric* Polynomial or number.  The product of two LinPolys is refused (it would be
bilinear) unless both are scalars (degree 0): then it is a
:class:`~sospoly.algebra.quadexpr.QuadExpr`.  All operations are vectorised over terms.
"""
from __future__ import annotations

import numbers

import numpy as np
import scipy.sparse as sp

from .polynomial import Polynomial, as_polynomial

__all__ = ["LinPoly"]


def _unique_rows(E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if E.shape[0] == 0:
        return E, np.zeros(0, dtype=np.int64)
    uniq, inv = np.unique(E, axis=0, return_inverse=True)
    return uniq, np.asarray(inv).ravel()


def _join(a, b):
    """The owner of a sum of expressions owned by ``a`` and ``b`` (None: no program's variables); ValueError when
    they are two different programs' (review 26a F9: their columns would alias each other)."""
    if a is None or a is b:
        return b if a is None else a
    if b is None:
        return a
    raise ValueError("an expression mixes decision variables of two different SOSPrograms")


def _is_quad(other) -> bool:
    return type(other).__name__ == "QuadExpr"


class LinPoly:
    """A polynomial in ``gens`` with coefficients affine in decision variables."""

    __slots__ = ("gens", "E", "const", "rows", "cols", "vals", "owner")

    def __init__(self, gens, E, const, rows=None, cols=None, vals=None, canonical=False, owner=None):
        self.gens = tuple(gens)
        self.owner = owner      # the token of the SOSProgram whose decision variables the columns index (or None)
        E = np.asarray(E, dtype=np.int64).reshape(-1, len(self.gens))
        const = np.asarray(const, dtype=float).reshape(-1)
        rows = np.zeros(0, np.int64) if rows is None else np.asarray(rows, dtype=np.int64)
        cols = np.zeros(0, np.int64) if cols is None else np.asarray(cols, dtype=np.int64)
        vals = np.zeros(0) if vals is None else np.asarray(vals, dtype=float)
        if not canonical:
            E, inv = _unique_rows(E)
            c2 = np.zeros(E.shape[0])
            np.add.at(c2, inv, const)
            const = c2
            rows = inv[rows] if rows.size else rows
            if rows.size:
                # merge duplicate (row, col) triplets
                key = rows * (int(cols.max()) + 1) + cols
                uk, kinv = np.unique(key, return_inverse=True)
                v2 = np.zeros(uk.size)
                np.add.at(v2, kinv, vals)
                ncols = int(cols.max()) + 1
                rows, cols, vals = uk // ncols, uk % ncols, v2
                keep = vals != 0.0
                rows, cols, vals = rows[keep], cols[keep], vals[keep]
        self.E, self.const, self.rows, self.cols, self.vals = E, const, rows, cols, vals

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_polynomial(cls, p: Polynomial, gens) -> LinPoly:
        p = p.with_gens(gens)
        if not p.terms:
            return cls(gens, np.zeros((0, len(gens)), np.int64), np.zeros(0), canonical=True)
        return cls(gens, p.exponents(), p.coefficients())

    @classmethod
    def variable_terms(cls, gens, E, var_index, owner=None) -> LinPoly:
        """sum_k x[var_index[k]] * v^E[k] (one decision variable per monomial)."""
        E = np.asarray(E, dtype=np.int64).reshape(-1, len(gens))
        m = E.shape[0]
        return cls(gens, E, np.zeros(m), np.arange(m), np.asarray(var_index), np.ones(m), owner=owner)

    def _coerce(self, other) -> LinPoly:
        if isinstance(other, LinPoly):
            if other.gens != self.gens:
                raise ValueError(f"LinPoly generators differ: {self.gens} vs {other.gens}")
            return other
        return LinPoly.from_polynomial(as_polynomial(other, self.gens), self.gens)

    # ------------------------------------------------------------------ arithmetic
    def __add__(self, other) -> LinPoly:
        if _is_quad(other):
            return NotImplemented
        o = self._coerce(other)
        m = self.E.shape[0]
        return LinPoly(self.gens, np.vstack([self.E, o.E]), np.concatenate([self.const, o.const]),
                       np.concatenate([self.rows, o.rows + m]), np.concatenate([self.cols, o.cols]),
                       np.concatenate([self.vals, o.vals]), owner=_join(self.owner, o.owner))

    __radd__ = __add__

    def __neg__(self) -> LinPoly:
        return self * -1.0

    def __sub__(self, other) -> LinPoly:
        if _is_quad(other):
            return NotImplemented
        return self + (-self._coerce(other))

    def __rsub__(self, other) -> LinPoly:
        return self._coerce(other) - self

    def __mul__(self, other) -> LinPoly:
        if isinstance(other, LinPoly):
            from .quadexpr import QuadExpr        # scalar x scalar: a quadratic form (else TypeError)

            return QuadExpr.product(self, other)
        if _is_quad(other):
            return NotImplemented
        if isinstance(other, (numbers.Real, np.floating, np.integer)) and not isinstance(other, bool):
            s = float(other)
            if not np.isfinite(s):
                raise ValueError("cannot scale by a non-finite number")
            return LinPoly(self.gens, self.E, self.const * s, self.rows, self.cols, self.vals * s, canonical=True,
                           owner=self.owner)
        p = as_polynomial(other, self.gens).with_gens(self.gens)
        if not p.terms:
            return LinPoly(self.gens, np.zeros((0, len(self.gens)), np.int64), np.zeros(0), canonical=True,
                           owner=self.owner)
        Ep, cp = p.exponents(), p.coefficients()
        t, m = Ep.shape[0], self.E.shape[0]
        E = (Ep[:, None, :] + self.E[None, :, :]).reshape(t * m, -1)
        const = (cp[:, None] * self.const[None, :]).reshape(-1)
        rows = (np.arange(t)[:, None] * m + self.rows[None, :]).reshape(-1)
        cols = np.tile(self.cols, t)
        vals = (cp[:, None] * self.vals[None, :]).reshape(-1)
        return LinPoly(self.gens, E, const, rows, cols, vals, owner=self.owner)

    __rmul__ = __mul__

    # ------------------------------------------------------------------ inspection
    @property
    def degree(self) -> int:
        """Degree of the monomials that carry a (possibly variable) coefficient."""
        live = np.zeros(self.E.shape[0], dtype=bool)
        live[self.const != 0] = True
        live[self.rows] = True
        return int(self.E[live].sum(axis=1).max()) if live.any() else -1

    def linear_matrix(self, n_vars: int) -> sp.csr_matrix:
        """The linear part as an (m x n_vars) sparse matrix."""
        return sp.csr_matrix((self.vals, (self.rows, self.cols)), shape=(self.E.shape[0], n_vars))

    def value(self, x: np.ndarray) -> Polynomial:
        """The numeric polynomial obtained for decision values ``x``."""
        coef = self.const.copy()
        if self.rows.size:
            np.add.at(coef, self.rows, self.vals * np.asarray(x)[self.cols])
        return Polynomial(self.gens, {tuple(int(k) for k in e): float(c) for e, c in zip(self.E, coef) if c != 0.0})

    def __repr__(self) -> str:
        return f"LinPoly({self.E.shape[0]} monomials over {self.gens}, {self.vals.size} variable terms)"
