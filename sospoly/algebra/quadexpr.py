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

__all__ = ["QuadExpr", "CURVATURE_RTOL", "convex_factor"]


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


#: a quadratic's matrix P counts as PSD when P + CURVATURE_RTOL Diag(P) is (:func:`convex_factor`): the negative
#: curvature tolerated along any direction is this fraction of that direction's own diagonal terms
CURVATURE_RTOL = 1e-10


def convex_factor(P: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None, float]:
    """F with F^T F = P (rows: the directions of positive curvature) for a symmetric P that is PSD at each
    direction's own scale, or (None, a direction v, its relative curvature) when it is not.

    The test is scale-free (review 26a F6): with D = Diag(P), C = D^{-1/2} P D^{-1/2} (unit diagonal: every
    variable rescaled to unit curvature, so the test does not depend on the variables' units), P is accepted when
    lambda_min(C) >= -:data:`CURVATURE_RTOL`, i.e. P + CURVATURE_RTOL D is PSD and dropping the negative part changes
    x^T P x by at most CURVATURE_RTOL sum_i P_ii x_i^2 -- each direction against its own terms.  Measuring
    lambda_min against the largest eigenvalue instead accepted 1e12 a^2 - 10 b^2 and minimised it as 1e12 a^2.  A
    negative diagonal entry (v = e_i, v^T P v = P_ii < 0), or a zero one with a non-zero entry in its row (P_ij^2 >
    P_ii P_jj = 0: v = t e_i - e_j for a large t), is indefinite exactly.  The relative curvature returned is
    v^T P v / sum_i P_ii v_i^2 (-1 for those exact cases)."""
    P = np.asarray(P, float)
    n = P.shape[0]
    d = np.diag(P).copy()
    if np.any(d < 0):
        i = int(np.argmin(d))
        return None, np.eye(n)[i], -1.0
    act = d > 0
    off = np.abs(P[~act]).sum(axis=1) if (~act).any() else np.zeros(0)
    if np.any(off > 0):
        i = int(np.nonzero(~act)[0][np.argmax(off)])
        j = int(np.argmax(np.abs(P[i])))
        v = np.zeros(n)
        v[j] = -1.0
        v[i] = np.sign(P[i, j]) * (1.0 + abs(P[j, j])) / max(abs(P[i, j]), 1e-300)
        return None, v, -1.0
    idx = np.nonzero(act)[0]
    if not idx.size:
        return np.zeros((0, n)), None, 0.0
    r = np.sqrt(d[idx])
    lam, V = np.linalg.eigh(P[np.ix_(idx, idx)] / np.outer(r, r))
    if lam[0] < -CURVATURE_RTOL:
        v = np.zeros(n)
        v[idx] = V[:, 0] / r
        return None, v, float(lam[0])
    keep = lam > 1e-14 * max(1.0, float(lam[-1]))
    F = np.zeros((int(keep.sum()), n))
    F[:, idx] = np.sqrt(lam[keep])[:, None] * V[:, keep].T * r[None, :]
    return F, None, 0.0
