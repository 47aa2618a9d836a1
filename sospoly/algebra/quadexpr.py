"""Quadratic expressions in the scalar decision variables of a program.

``QuadExpr`` is ``x^T P x + l^T x + c`` over the program's global decision index x, with P
stored as COO triplets (summed on use) and the affine part ``l^T x + c`` a scalar
:class:`~sospoly.algebra.linpoly.LinPoly`.  It is what the product of two *scalar* (degree-0)
LinPolys gives, e.g. ``a * a`` for a decision scalar a, and what
:meth:`sospoly.SOSProgram.minimize` accepts as a convex objective (lowered through an epigraph
variable and a rotated second-order cone, :mod:`sospoly.lowering.conic`).
"""
from __future__ import annotations

import numbers

import numpy as np
import scipy.sparse as sp

__all__ = ["QuadExpr"]


def _scalar_parts(p) -> tuple[float, np.ndarray, np.ndarray]:
    """(constant, columns, values) of a scalar LinPoly."""
    if p.degree > 0:
        raise TypeError("the product of two decision-dependent polynomials is not affine; only scalar "
                        "(degree-0) decision expressions multiply into a quadratic")
    return float(p.const.sum()), p.cols.copy(), p.vals.copy()


class QuadExpr:
    """``x^T P x + affine`` with P given by triplets ``(qi, qj, qv)`` (duplicates add)."""

    __slots__ = ("affine", "qi", "qj", "qv")

    def __init__(self, affine, qi, qj, qv):
        self.affine = affine
        self.qi = np.asarray(qi, np.int64)
        self.qj = np.asarray(qj, np.int64)
        self.qv = np.asarray(qv, float)

    @classmethod
    def product(cls, a, b) -> QuadExpr:
        """(c_a + l_a^T x)(c_b + l_b^T x) for scalar LinPolys a and b."""
        ca, ia, va = _scalar_parts(a)
        cb, ib, vb = _scalar_parts(b)
        affine = a * cb + b * ca - ca * cb
        qi = np.repeat(ia, ib.size)
        qj = np.tile(ib, ia.size)
        qv = np.outer(va, vb).ravel()
        return cls(affine, qi, qj, qv)

    @property
    def gens(self) -> tuple:
        return self.affine.gens

    @property
    def degree(self) -> int:
        return 0

    def _coerce(self, other) -> QuadExpr:
        if isinstance(other, QuadExpr):
            return other
        z = np.zeros(0)
        return QuadExpr(self.affine * 0.0 + other, z, z, z)

    def __add__(self, other) -> QuadExpr:
        o = self._coerce(other)
        return QuadExpr(self.affine + o.affine, np.concatenate([self.qi, o.qi]), np.concatenate([self.qj, o.qj]),
                        np.concatenate([self.qv, o.qv]))

    __radd__ = __add__

    def __mul__(self, other) -> QuadExpr:
        if not isinstance(other, (numbers.Real, np.floating, np.integer)) or isinstance(other, bool):
            raise TypeError("a quadratic expression can only be scaled by a number")
        s = float(other)
        if not np.isfinite(s):
            raise ValueError("cannot scale by a non-finite number")
        return QuadExpr(self.affine * s, self.qi, self.qj, self.qv * s)

    __rmul__ = __mul__

    def __neg__(self) -> QuadExpr:
        return self * -1.0

    def __sub__(self, other) -> QuadExpr:
        return self + (-self._coerce(other))

    def __rsub__(self, other) -> QuadExpr:
        return self._coerce(other) - self

    def matrix(self, n_vars: int) -> np.ndarray:
        """The symmetric P (dense, n_vars x n_vars) with x^T P x the quadratic part."""
        P = sp.coo_matrix((self.qv, (self.qi, self.qj)), shape=(n_vars, n_vars)).toarray()
        return 0.5 * (P + P.T)

    def value(self, x: np.ndarray) -> float:
        """The number x^T P x + l^T x + c at decision values ``x``."""
        x = np.asarray(x, float)
        quad = float(np.sum(self.qv * x[self.qi] * x[self.qj]))
        return quad + float(self.affine.value(x).coefficient((0,) * len(self.gens)))

    def __repr__(self) -> str:
        return f"QuadExpr({self.qv.size} quadratic terms over decision variables)"
